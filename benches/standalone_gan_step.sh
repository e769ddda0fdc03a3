#!/usr/bin/env bash
# Builds crates/patch-gan/examples/gan_step.rs as a program outside this workspace would: a
# cargo project of its own (default release profile, none of this workspace's settings) that
# depends on patch-gan by path, plus the crates of patch-gan's API (candle-core, candle-nn,
# rand) and rayon (for gan_step's --join-pool), and prints the binary's path.
# `STANDALONE=1 bash benches/compare_gan_peer.sh` runs the peer table with it.
#   bash benches/standalone_gan_step.sh [DIR]     (default: $TMPDIR/patch-gan-user)
# The workspace's Cargo.lock is copied in, so both builds take the same crate versions.
set -euo pipefail
REPO=$(cd "$(dirname "$0")/.." && pwd)
DIR=${1:-${TMPDIR:-/tmp}/patch-gan-user}
mkdir -p "$DIR"
cat > "$DIR/Cargo.toml" <<TOML
[package]
name = "patch-gan-user"
version = "0.1.0"
edition = "2021"
publish = false

[dependencies]
patch-gan = { path = "$REPO/crates/patch-gan" }
candle-core = "0.11"
candle-nn = "0.11"
rand = "0.9"
rayon = "1.10"

[[bin]]
name = "gan_step"
path = "$REPO/crates/patch-gan/examples/gan_step.rs"

# A workspace of its own: not a member of the repository's.
[workspace]
TOML
[ -f "$DIR/Cargo.lock" ] || cp "$REPO/Cargo.lock" "$DIR/Cargo.lock"
cargo build --release --manifest-path "$DIR/Cargo.toml" >&2
echo "$DIR/target/release/gan_step"
