#!/usr/bin/env bash
# Packages the VS Code extension into editors/vscode/plantc-<version>.vsix
# from a clean checkout: installs the pinned npm dependencies
# (package-lock.json) and runs vsce. Needs node >= 18 and npm.
# Install the result with `code --install-extension plantc-<version>.vsix`.
set -euo pipefail
cd "$(dirname "$0")"
npm ci --no-audit --no-fund
npm test
version=$(node -p "require('./package.json').version")
npx vsce package --allow-missing-repository -o "plantc-${version}.vsix"
echo "packaged editors/vscode/plantc-${version}.vsix"
