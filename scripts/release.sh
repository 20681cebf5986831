#!/usr/bin/env bash
# Builds the release binary of plantc and packs it for distribution:
#
#     bash scripts/release.sh [TARGET]
#
# writes dist/plantc-<version>-<target>.tar.gz (the `plantc` binary, README,
# the tutorial, the licences and the bundled models) and its .sha256, from
# Cargo.lock as committed (--locked). TARGET is a rustc target triple
# (default: this machine's); another target needs its standard library
# (`rustup target add TARGET`) and a linker for it. The crates themselves
# go to crates.io with `cargo publish -p NAME` in dependency order (fsio,
# derive, codegen, runtime, identify, lsp, plantc); `cargo package
# --workspace --exclude rotpen-controller` checks them first (the example
# reads the repository's models and is not published).
set -euo pipefail
cd "$(dirname "$0")/.."
host=$(rustc -vV | sed -n 's/^host: //p')
target="${1:-$host}"
version=$(sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -1)
name="plantc-$version-$target"
if [ "$target" = "$host" ]; then
    # the same build as `cargo build --release` (shares target/release)
    cargo build --release --locked -p plantc
    bin="target/release/plantc"
else
    cargo build --release --locked -p plantc --target "$target"
    bin="target/$target/release/plantc"
fi
[ -x "$bin" ] || bin="$bin.exe"
stage="dist/$name"
rm -rf "$stage"
mkdir -p "$stage/docs"
cp "$bin" "$stage/"
cp README.md LICENSE-MIT LICENSE-APACHE "$stage/"
cp docs/tutorial.md "$stage/docs/"
cp -r models "$stage/"
tar -C dist -czf "dist/$name.tar.gz" "$name"
rm -rf "$stage"
(cd dist && sha256sum "$name.tar.gz" > "$name.tar.gz.sha256")
"$bin" --version
echo "dist/$name.tar.gz ($(du -h "dist/$name.tar.gz" | cut -f1)), sha256 $(cut -d' ' -f1 "dist/$name.tar.gz.sha256")"
