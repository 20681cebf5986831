// VS Code extension for plantc model files: the language, its highlighting
// (syntaxes/plant.tmLanguage.json) and the language server (`plantc lsp`).
'use strict';

const vscode = require('vscode');
const { LanguageClient, TransportKind } = require('vscode-languageclient/node');

let client;

function activate(context) {
  const config = vscode.workspace.getConfiguration('plantc');
  const command = config.get('server.path') || 'plantc';
  const args = ['lsp', ...(config.get('server.extraArgs') || [])];
  const serverOptions = {
    run: { command, args, transport: TransportKind.stdio },
    debug: { command, args, transport: TransportKind.stdio },
  };
  const clientOptions = {
    documentSelector: [
      { scheme: 'file', language: 'plant' },
      { scheme: 'untitled', language: 'plant' },
    ],
  };
  client = new LanguageClient('plantc', 'plantc language server', serverOptions, clientOptions);
  client.start().catch((e) => {
    vscode.window.showErrorMessage(
      `plantc: could not start \`${command} lsp\` (${e.message}). ` +
        'Install plantc (cargo install --path plantc) or set "plantc.server.path".'
    );
  });
  context.subscriptions.push({ dispose: () => client && client.stop() });
}

function deactivate() {
  return client ? client.stop() : undefined;
}

module.exports = { activate, deactivate };
