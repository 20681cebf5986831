"""A few hundred mutated model texts: errors, never an abort."""

import os
import subprocess
import sys

from conftest import ROOT

SCRIPT = r'''
import os, random, sys
import plantc
root = sys.argv[1]
n = int(sys.argv[2])
texts = [open(os.path.join(root, "models", f), encoding="utf-8").read()
         for f in ("rotary_pendulum.plant", "cart_pole.plant", "double_pendulum.plant")]
alphabet = list("()[]{}+-*/^'=,.:;#\"\\ \n\t0123456789eEabcxyz_") + ["sin(", "sqrt(", "1e308", "1e-308", "0/0", "\u00e9", "\U0001F600"]
rng = random.Random(29)
kinds = {"ok": 0, "ModelError": 0}
for i in range(n):
    t = rng.choice(texts)
    for _ in range(rng.randint(1, 4)):
        op = rng.randrange(6)
        k = rng.randrange(len(t) + 1)
        if op == 0:    # delete a span
            t = t[:k] + t[k + rng.randint(1, 20):]
        elif op == 1:  # insert tokens
            t = t[:k] + "".join(rng.choice(alphabet) for _ in range(rng.randint(1, 5))) + t[k:]
        elif op == 2:  # duplicate a line
            lines = t.split("\n"); j = rng.randrange(len(lines)); lines.insert(j, lines[j]); t = "\n".join(lines)
        elif op == 3:  # swap two lines
            lines = t.split("\n"); a, b = rng.randrange(len(lines)), rng.randrange(len(lines)); lines[a], lines[b] = lines[b], lines[a]; t = "\n".join(lines)
        elif op == 4:  # deep nesting
            t = t[:k] + "(" * rng.choice([10, 1000, 20000]) + t[k:]
        else:          # change a number
            t = t[:k] + rng.choice(["0", "-1", "1e300", "nan", "inf"]) + t[k:]
    with open(os.path.join(sys.argv[3], "last.plant"), "w", encoding="utf-8") as f:
        f.write(t)
    try:
        m = plantc.Model.from_text(t, name="mutant.plant")
    except plantc.ModelError as e:
        assert e.line is None or e.line >= 1, e.line
        kinds["ModelError"] += 1
        continue
    kinds["ok"] += 1
    for call in (lambda: m.derive(), lambda: m.linearize()):
        try:
            call()
        except (plantc.PlantcError, ValueError) as e:
            assert "internal error" not in str(e), (i, str(e))
print(kinds)
'''


def test_mutated_models_never_abort(tmp_path):
    n = int(os.environ.get("PLANTC_FUZZ_CASES", "300"))
    r = subprocess.run(
        [sys.executable, "-c", SCRIPT, ROOT, str(n), str(tmp_path)],
        capture_output=True,
        text=True,
    )
    last = (tmp_path / "last.plant")
    assert r.returncode == 0, (
        f"exit {r.returncode}\n{r.stderr[-3000:]}\nlast mutant:\n"
        + (last.read_text(encoding="utf-8") if last.exists() else "")
    )
    assert "ModelError" in r.stdout
