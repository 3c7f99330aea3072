#!/usr/bin/env bash
# The generated crate on targets that are not x86 (issue 66, item 1): its
# square root is SSE2's instruction on x86, VSQRT.F32 on a hard-float ARM core
# in the f32 build, and libm's elsewhere (an instruction on aarch64, software
# on an FPU-less core). This script
#   1. builds the no_std crate (every kernel, through `dispatch`) for
#      Cortex-M4F (f32 and f64), Cortex-M0 (no FPU), bare aarch64 and a
#      RISC-V core without an FPU, and checks in the assembly which square
#      root each one got;
#   2. runs the whole verification suite (kernels against the IR evaluator,
#      CasADi, finite differences, the 50-digit references, and the f32
#      build's probe) on 64-bit and 32-bit ARM Linux under qemu.
#
# Usage: scripts/cross_check.sh           (about 5 minutes on 2 cores)
#
# Building core and std for these targets takes `-Zbuild-std`, so a nightly
# toolchain and its standard library's source. rustup's `rust-src` cannot be
# fetched on a machine that reaches only crates.io, PyPI and Debian: the
# script then uses Debian's `rust-src` package of the nightly's version
# (pinned by checksum), in a private copy of the nightly's sysroot under
# target/cross (hard links), so that nothing of the machine's toolchain is
# changed. Without a nightly, or without a matching source, it says so and
# exits 0: this is a check of the generated code, not of the machine.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
work=$root/target/cross

skip() { echo "cross check skipped: $*"; exit 0; }

nightly=$(rustup toolchain list 2>/dev/null | awk '/^nightly/{print $1; exit}')
[ -n "$nightly" ] || skip "no nightly toolchain (-Zbuild-std needs one)"
sysroot=$(rustup run "$nightly" rustc --print sysroot)
version=$(rustup run "$nightly" rustc -V)

if [ -f "$sysroot/lib/rustlib/src/rust/library/Cargo.lock" ]; then
  toolchain=$sysroot
else
  # Debian's source of the release the nightly became (sid); cargo only
  # compiles `library/` from it
  case "$version" in
    "rustc 1.97."*)
      deb=rust-src_1.97.1+dfsg1-1_all.deb
      sum=d0637f8f464234ffb12baa55fc0e851f5f9dcfd0199c1a0922e4488a4f591992
      src=usr/src/rustc-1.97.1 ;;
    *) skip "no pinned source for $version (rustup component add rust-src --toolchain $nightly)" ;;
  esac
  toolchain=$work/toolchain
  if [ ! -f "$toolchain/lib/rustlib/src/rust/library/Cargo.lock" ]; then
    mkdir -p "$work"
    if [ ! -f "$work/$deb" ]; then
      curl -sfL -m 300 -o "$work/$deb.part" "http://deb.debian.org/debian/pool/main/r/rustc/$deb" ||
        skip "Debian's pool no longer has $deb (rustup component add rust-src --toolchain $nightly)"
      mv "$work/$deb.part" "$work/$deb"
    fi
    echo "$sum  $work/$deb" | sha256sum -c --quiet - || { echo "cross check: $deb: checksum mismatch" >&2; exit 1; }
    rm -rf "$work/rust-src" "$toolchain"
    dpkg-deb -x "$work/$deb" "$work/rust-src"
    # rustc finds its sysroot from its own path: a hard-linked copy (a plain
    # copy on another file system) with the source where rust-src goes
    cp -al "$sysroot" "$toolchain" 2>/dev/null || cp -a "$sysroot" "$toolchain"
    mkdir -p "$toolchain/lib/rustlib/src"
    ln -s "$work/rust-src/$src" "$toolchain/lib/rustlib/src/rust"
  fi
fi

# Cross linkers and qemu's user mode (Debian's packages) for the runs
need=()
command -v qemu-aarch64 >/dev/null || need+=(qemu-user)
command -v aarch64-linux-gnu-gcc >/dev/null || need+=(gcc-aarch64-linux-gnu libc6-dev-arm64-cross)
command -v arm-linux-gnueabihf-gcc >/dev/null || need+=(gcc-arm-linux-gnueabihf libc6-dev-armhf-cross)
if [ ${#need[@]} -gt 0 ]; then
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need[@]}" >/dev/null ||
    skip "could not install ${need[*]}"
fi

export PATH="$toolchain/bin:$PATH" RUSTC="$toolchain/bin/rustc" CARGO_TARGET_DIR="$work/target"
export CARGO_INCREMENTAL=0
cargo="$toolchain/bin/cargo"
echo "toolchain: $version, library source from $(readlink -f "$toolchain/lib/rustlib/src/rust")"

# 1. Builds, and the square root in each build's assembly
fail=0
asm_of() { # target, features -> the generated crate's assembly
  local target=$1 features=$2
  "$cargo" rustc -q -Zbuild-std=core --target "$target" -p kinegen-generated --release \
    --features "$features" -- --emit asm -C codegen-units=1 >&2
  ls -t "$CARGO_TARGET_DIR/$target/release/deps/"kinegen_generated-*.s | head -1
}
expect() { # target, features, what the square root must be, grep pattern for it[, one it must not have]
  local target=$1 features=$2 what=$3 pattern=$4 forbidden=${5:-} file
  file=$(asm_of "$target" "$features")
  if grep -qE "$pattern" "$file" && { [ -z "$forbidden" ] || ! grep -qE "$forbidden" "$file"; }; then
    printf '  ok    %-30s %-13s %s\n' "$target" "$features" "$what"
  else
    printf '  FAIL  %-30s %-13s expected %s\n' "$target" "$features" "$what"
    fail=1
  fi
}
echo "builds (no_std, every kernel):"
# the f32 build on an M4F must not reach libm's software square root at all
expect thumbv7em-none-eabihf dispatch,f32 "VSQRT.F32" 'vsqrt\.f32' 'libm.*4sqrt5sqrtf'
expect thumbv7em-none-eabihf dispatch "libm's sqrt (no f64 FPU)" 'bl[[:space:]].*libm.*4sqrt4sqrt'
expect thumbv6m-none-eabi dispatch,f32 "libm's sqrtf (no FPU)" 'bl[[:space:]].*libm.*4sqrt5sqrtf'
expect aarch64-unknown-none dispatch "FSQRT" 'fsqrt[[:space:]]+d'
expect riscv32imac-unknown-none-elf dispatch "libm's sqrt (no FPU)" 'call[[:space:]].*libm.*4sqrt4sqrt'

# 2. The verification suite on ARM Linux under qemu
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER="qemu-aarch64 -L /usr/aarch64-linux-gnu"
export CARGO_TARGET_ARMV7_UNKNOWN_LINUX_GNUEABIHF_LINKER=arm-linux-gnueabihf-gcc
export CARGO_TARGET_ARMV7_UNKNOWN_LINUX_GNUEABIHF_RUNNER="qemu-arm -L /usr/arm-linux-gnueabihf"
for target in aarch64-unknown-linux-gnu armv7-unknown-linux-gnueabihf; do
  # through the environment, so that the f32 test's own `cargo run` of the
  # probe builds it for this target too and runs it under qemu
  log=$work/$target.log
  if CARGO_BUILD_TARGET=$target CARGO_UNSTABLE_BUILD_STD=std,panic_abort,panic_unwind \
    "$cargo" test -p kinegen-verify >"$log" 2>&1; then
    passed=$(grep -oE '^test result: ok\. [0-9]+' "$log" | awk '{s+=$4} END {print s}')
    printf '  ok    %-30s verification suite under qemu: %s tests passed\n' "$target" "$passed"
  else
    printf '  FAIL  %-30s verification suite under qemu (%s)\n' "$target" "$log"
    grep -E 'panicked|FAILED|error(\[|:)' "$log" | head -10
    fail=1
  fi
done
exit $fail
