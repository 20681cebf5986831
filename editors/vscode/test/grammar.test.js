// Tokenizes the repository's models with the TextMate grammar (the engine VS
// Code uses) and checks the scopes of characteristic tokens. Run: npm test.
'use strict';

const test = require('node:test');
const assert = require('node:assert');
const fs = require('fs');
const path = require('path');
const vsctm = require('vscode-textmate');
const oniguruma = require('vscode-oniguruma');

const root = path.join(__dirname, '..', '..', '..');
const wasm = fs.readFileSync(require.resolve('vscode-oniguruma/release/onig.wasm')).buffer;
const onigLib = oniguruma.loadWASM(wasm).then(() => ({
  createOnigScanner: (p) => new oniguruma.OnigScanner(p),
  createOnigString: (s) => new oniguruma.OnigString(s),
}));
const grammarPath = path.join(__dirname, '..', 'syntaxes', 'plant.tmLanguage.json');
const registry = new vsctm.Registry({
  onigLib,
  loadGrammar: async () =>
    vsctm.parseRawGrammar(fs.readFileSync(grammarPath, 'utf8'), grammarPath),
});

/** [{text, scopes}] of every token of a file. */
async function tokenize(text) {
  const g = await registry.loadGrammar('source.plant');
  let state = vsctm.INITIAL;
  const out = [];
  for (const line of text.split('\n')) {
    const r = g.tokenizeLine(line, state);
    for (const t of r.tokens) {
      out.push({ text: line.substring(t.startIndex, t.endIndex), scopes: t.scopes.join(' ') });
    }
    state = r.ruleStack;
  }
  return out;
}

function scopeOf(tokens, text, nth = 0) {
  const found = tokens.filter((t) => t.text === text);
  assert.ok(found.length > nth, `token ${JSON.stringify(text)} not found`);
  return found[nth].scopes;
}

test('rotary pendulum: declarations, units, effects, derivatives', async () => {
  const text = fs.readFileSync(path.join(root, 'models', 'rotary_pendulum.plant'), 'utf8');
  const t = await tokenize(text);
  assert.match(scopeOf(t, 'model'), /keyword\.declaration/);
  assert.match(scopeOf(t, 'parameter'), /keyword\.declaration\.parameter/);
  assert.match(scopeOf(t, 'J1'), /variable\.other\.constant/);
  assert.match(scopeOf(t, 'kg'), /meta\.unit.*support\.type\.unit/);
  assert.match(scopeOf(t, 'angle'), /support\.type/);
  assert.match(scopeOf(t, 'viscous_friction'), /support\.function\.effect/);
  assert.match(scopeOf(t, 'sin'), /support\.function\.builtin/);
  assert.match(scopeOf(t, "'"), /keyword\.operator\.derivative/);
  assert.match(scopeOf(t, '# Arm (Table 3)'), /comment\.line/);
  assert.match(scopeOf(t, '9.98e-4'), /constant\.numeric/);
  assert.match(scopeOf(t, '3.464i'), /constant\.numeric/);
  assert.match(scopeOf(t, 'estimate'), /keyword\.other/);
  assert.match(scopeOf(t, 'pole_placement'), /entity\.name\.namespace/);
  // lists after `limits`, `Q`, `R`, `poles` are not units
  for (const kw of ['limits', 'Q', 'R', 'poles']) {
    const i = t.findIndex((x) => x.text === kw);
    assert.ok(i >= 0, kw);
    const end = t.findIndex((x, j) => j > i && x.text.includes(']'));
    for (const x of t.slice(i + 1, end + 1)) {
      assert.doesNotMatch(x.scopes, /meta\.unit/, `${kw}: ${x.text}`);
    }
  }
});

test('every model tokenizes with comments and strings closed on their line', async () => {
  for (const m of fs.readdirSync(path.join(root, 'models')).filter((f) => f.endsWith('.plant'))) {
    const text = fs.readFileSync(path.join(root, 'models', m), 'utf8');
    const t = await tokenize(text + '\nparameter after = 1 [kg]\n');
    // a string or unit left open would swallow the last line
    assert.match(scopeOf(t, 'after'), /variable\.other\.constant/, m);
    assert.doesNotMatch(scopeOf(t, 'after'), /string|comment|meta\.unit/, m);
  }
});

test('hybrid, sliding-mode and recorded controllers, rig effects', async () => {
  const rp = await tokenize(fs.readFileSync(path.join(root, 'models', 'rotary_pendulum.plant'), 'utf8'));
  for (const kw of ['wrap', 'mode', 'switch', 'when', 'surface']) {
    assert.match(scopeOf(rp, kw), /keyword\.other/, kw);
  }
  // `swing_up` is a controller's name and, after `mode name = controller`, a marker
  assert.ok(rp.some((x) => x.text === 'swing_up' && /keyword\.other/.test(x.scopes)));
  assert.match(scopeOf(rp, '->'), /keyword\.operator/);
  assert.match(scopeOf(rp, 'sat'), /support\.function\.builtin/);
  assert.match(scopeOf(rp, 'energy'), /support\.function\.builtin/);
  const qube = await tokenize(fs.readFileSync(path.join(root, 'models', 'qube_servo.plant'), 'utf8'));
  assert.match(scopeOf(qube, 'recorded'), /keyword\.declaration/);
  assert.match(scopeOf(qube, 'qube_pd'), /entity\.name\.namespace/);
  assert.match(scopeOf(qube, 'signal'), /keyword\.other/);
  assert.match(scopeOf(qube, 'derivative'), /support\.function\.builtin/);
  const t = await tokenize(
    'inertia theta = added_inertia(Jr)\nactuator Vm = saturation(L)\nforce q = cogging(A, N) + speed_limit(v, c)\n' +
      'switch a -> b when abs(alpha) < 15 [deg] and theta >= 0 or q <= 1\n',
  );
  assert.match(scopeOf(t, 'inertia'), /keyword\.declaration/);
  for (const e of ['added_inertia', 'saturation', 'cogging', 'speed_limit']) {
    assert.match(scopeOf(t, e), /support\.function\.effect/, e);
  }
  assert.match(scopeOf(t, 'and'), /keyword\.operator\.logical/);
  assert.match(scopeOf(t, 'or'), /keyword\.operator\.logical/);
  assert.match(scopeOf(t, 'deg'), /meta\.unit/);
});
