#!/usr/bin/env bash
# Regenerates the parser (src/: parser.c, grammar.json, node-types.json,
# tree_sitter/*.h) from grammar.js with the pinned tree-sitter CLI, then runs
# the CLI's corpus tests. Commit src/ with grammar.js: `cargo test -p
# tree-sitter-plant` (in CI) compiles src/parser.c and fails when src/ lacks
# a rule or keyword of grammar.js.
#
#     bash editors/tree-sitter-plant/generate.sh
#
# The CLI, version $VERSION below, is taken from (first found):
#   - $TREE_SITTER (a path to the binary), or `tree-sitter` on the PATH if it
#     is that version;
#   - a cache, ${XDG_CACHE_HOME:-~/.cache}/plantc/tree-sitter-cli-$VERSION,
#     filled on first use by npm (`tree-sitter-cli@$VERSION`, whose install
#     script downloads the binary from GitHub) or, where only the package
#     registries are reachable, by `cargo install tree-sitter-cli --locked`
#     (builds it: about 10 minutes on 2 cores).
# Needs node (the CLI evaluates grammar.js with it).
set -euo pipefail
cd "$(dirname "$0")"
VERSION=0.25.9
cache="${XDG_CACHE_HOME:-$HOME/.cache}/plantc/tree-sitter-cli-$VERSION"
version_of() { "$1" --version 2>/dev/null | awk '{print $2}'; }
cli=""
if [ -n "${TREE_SITTER:-}" ]; then
    cli="$TREE_SITTER"
elif command -v tree-sitter >/dev/null 2>&1 && [ "$(version_of tree-sitter)" = "$VERSION" ]; then
    cli=tree-sitter
elif [ -x "$cache/bin/tree-sitter" ]; then
    cli="$cache/bin/tree-sitter"
elif [ -x "$cache/node_modules/.bin/tree-sitter" ]; then
    cli="$cache/node_modules/.bin/tree-sitter"
else
    mkdir -p "$cache"
    if npm install --prefix "$cache" --no-audit --no-fund "tree-sitter-cli@$VERSION" >&2 \
        && [ -x "$cache/node_modules/.bin/tree-sitter" ]; then
        cli="$cache/node_modules/.bin/tree-sitter"
    else
        echo "npm could not install the CLI; building it with cargo" >&2
        cargo install tree-sitter-cli --version "$VERSION" --locked --root "$cache"
        cli="$cache/bin/tree-sitter"
    fi
fi
if [ "$(version_of "$cli")" != "$VERSION" ]; then
    echo "error: $cli is tree-sitter $(version_of "$cli"), expected $VERSION" >&2
    exit 1
fi
"$cli" generate
"$cli" test
echo "generated src/ with tree-sitter $VERSION; now: cargo test -p tree-sitter-plant"
