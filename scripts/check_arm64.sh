#!/usr/bin/env bash
# Build eppf and run its kernel, descriptor and equivalence tests on an emulated aarch64 CPU.
#
# Usage (as root, on a Debian/Ubuntu x86-64 host, from anywhere in the checkout):
#
#     apt-get install qemu-user-static binfmt-support debootstrap rsync
#     scripts/check_arm64.sh                  # the default test selection
#     scripts/check_arm64.sh tests/utils      # or any pytest arguments
#
# What it does:
#   1. makes (once) a Debian bookworm arm64 root in build/arm64-root with
#      `debootstrap --arch=arm64 --foreign`, its second stage run through
#      qemu-user (the kernel's binfmt_misc hands aarch64 binaries to
#      qemu-aarch64-static), plus a venv there with aarch64 wheels from PyPI
#      (Debian's own numpy and scikit-learn are older than eppf's minimums);
#   2. copies the working tree (tracked and untracked, not ignored files) to
#      /src/eppf in that root, keeping the kernels built there before, so
#      only changed kernels recompile;
#   3. builds the kernels in place (the portable, non-SIMD code: the SIMD
#      paths are compiled on x86-64 only, see eppf/utils/_cpu.h);
#   4. runs `python tests/fingerprints.py --check tests/data/fingerprints.json`
#      (it lists every output that differs from the recorded references) and
#      pytest -x -q on the kernel, descriptor and equivalence tests (or on the
#      arguments given).
#
# It prints each step with its time and the pytest summary, and exits non-zero
# if the build, the tests or the fingerprint check fail. Emulation is slow. On
# two busy cores the first run took about 18 min for the root, 35 min for the
# venv (about 5 GB: PyPI's aarch64 torch 2.13.0 is its CUDA build, "+cu130",
# and pulls NVIDIA's libraries, which run on CPU alone), 17 min to compile the
# kernels, 5 min for the fingerprints and about 25 min for the tests; later
# runs recompile only the kernels whose sources changed. Delete build/arm64-root
# to start afresh. Settings (environment variables):
#   EPPF_ARM64_ROOT    the arm64 root (default build/arm64-root in the checkout)
#   EPPF_ARM64_MIRROR  the Debian mirror (default http://deb.debian.org/debian)
#   EPPF_ARM64_TORCH   the torch version for the venv (default: constraints.txt's)
#   EPPF_ARM64_JOBS    parallel compile jobs (default: all cores)
#   EPPF_ARM64_NO_FINGERPRINTS=1  skip the fingerprint check
set -euo pipefail

REPO=$(git -C "$(dirname "$0")" rev-parse --show-toplevel)
ROOT=${EPPF_ARM64_ROOT:-$REPO/build/arm64-root}
MIRROR=${EPPF_ARM64_MIRROR:-http://deb.debian.org/debian}
TORCH=${EPPF_ARM64_TORCH:-$(sed -n 's/^torch==//p' "$REPO/constraints.txt")}
JOBS=${EPPF_ARM64_JOBS:-$(nproc)}
VENV=/opt/eppf-venv
SRC=/src/eppf
if [ $# -gt 0 ]; then
    TESTS=("$@")
else
    TESTS=(tests/descriptors tests/preprocessing/test_normals.py tests/test_equivalence.py tests/utils)
fi

T0=$(date +%s)
step() { printf '\n=== [%4ds] %s\n' $(($(date +%s) - T0)) "$*"; }
die() { echo "check_arm64: $*" >&2; exit 1; }

[ "$(id -u)" = 0 ] || die "needs root (debootstrap, chroot and mounts)"
for tool in qemu-aarch64-static debootstrap rsync; do
    command -v "$tool" >/dev/null || die "$tool not found: apt-get install qemu-user-static binfmt-support debootstrap rsync"
done

# aarch64 binaries must run through qemu: binfmt_misc mounted and the qemu-aarch64 entry enabled.
if [ ! -e /proc/sys/fs/binfmt_misc/register ]; then
    mount -t binfmt_misc binfmt_misc /proc/sys/fs/binfmt_misc || die "cannot mount binfmt_misc"
fi
if [ ! -e /proc/sys/fs/binfmt_misc/qemu-aarch64 ]; then
    update-binfmts --enable qemu-aarch64 || die "cannot register qemu-aarch64 with binfmt_misc"
fi

in_root() {
    chroot "$ROOT" /usr/bin/env -i HOME=/root PATH=$VENV/bin:/usr/sbin:/usr/bin:/sbin:/bin LANG=C.UTF-8 PYTHONPATH=$SRC \
        PIP_CERT=/etc/eppf-host-ca.crt PIP_DISABLE_PIP_VERSION_CHECK=1 ${https_proxy:+https_proxy=$https_proxy} "$@"
}

mounted=()
cleanup() {
    local i
    for ((i = ${#mounted[@]} - 1; i >= 0; i--)); do umount -l "${mounted[i]}" 2>/dev/null || true; done
}
trap cleanup EXIT
trap "exit 130" INT TERM
mount_in_root() {
    mountpoint -q "$ROOT/$1" && return
    mount --bind "/$1" "$ROOT/$1"
    mounted+=("$ROOT/$1")
}

if [ ! -e "$ROOT/.eppf-root-done" ]; then
    step "debootstrap bookworm arm64 into $ROOT (first stage)"
    rm -rf "$ROOT"
    mkdir -p "$ROOT"
    debootstrap --arch=arm64 --foreign --variant=minbase \
        --include=python3,python3-venv,python3-dev,gcc,g++,libc6-dev,ca-certificates \
        bookworm "$ROOT" "$MIRROR"
    # a copy of qemu inside, for hosts whose binfmt entry lacks the F (fix-binary) flag
    cp /usr/bin/qemu-aarch64-static "$ROOT/usr/bin/"
    step "debootstrap second stage (emulated)"
    chroot "$ROOT" /debootstrap/debootstrap --second-stage
    touch "$ROOT/.eppf-root-done"
fi
# no /sys: torch's cpuinfo then reads the host's CPUs and crashes under qemu
mount_in_root proc
mount_in_root dev
cp /etc/resolv.conf "$ROOT/etc/resolv.conf"
# pip in the root trusts what the host trusts (a host behind a TLS-inspecting proxy adds its CA there)
HOST_CA=${SSL_CERT_FILE:-/etc/ssl/certs/ca-certificates.crt}
[ -f "$HOST_CA" ] && cp "$HOST_CA" "$ROOT/etc/eppf-host-ca.crt"

REQS="numpy scipy scikit-learn joblib threadpoolctl tqdm skorch Cython setuptools wheel pytest torch==$TORCH"
if [ "$(cat "$ROOT/.eppf-venv-done" 2>/dev/null)" != "$REQS" ]; then
    step "venv with aarch64 wheels from PyPI: $REQS"
    in_root python3 -m venv --clear $VENV
    in_root pip install -q --upgrade pip
    # torch's aarch64 wheels on PyPI are CPU builds
    in_root pip install -q --only-binary=:all: $REQS
    echo "$REQS" >"$ROOT/.eppf-venv-done"
fi

step "copy the working tree to $SRC (kernels built before are kept)"
mkdir -p "$ROOT$SRC"
rsync -a --delete --exclude=/.git --exclude=/build/ --filter=':- .gitignore' "$REPO/" "$ROOT$SRC/"

step "build the kernels (aarch64, portable code)"
in_root sh -c "cd $SRC && python setup.py -q build_ext --inplace -j $JOBS" 2>&1 | grep -v '^Compiling \|^\[' || true
in_root sh -c "cd $SRC && python -c 'import eppf.descriptors._eppf_fast'" || die "the build failed"

step "environment"
in_root sh -c "cd $SRC && python - <<'EOF'
import platform, numpy, scipy, sklearn, torch
print('machine', platform.machine(), '| python', platform.python_version(), '| numpy', numpy.__version__,
      '| scipy', scipy.__version__, '| scikit-learn', sklearn.__version__, '| torch', torch.__version__)
import eppf
print('eppf kernel levels:', eppf.simd_levels())
EOF"

status=0
if [ -z "${EPPF_ARM64_NO_FINGERPRINTS:-}" ]; then
    step "python tests/fingerprints.py --check tests/data/fingerprints.json"
    in_root sh -c "cd $SRC && python tests/fingerprints.py --check tests/data/fingerprints.json" || status=1
fi

step "pytest -x -q ${TESTS[*]}"
in_root sh -c "cd $SRC && python -m pytest -x -q -p no:cacheprovider $(printf '%q ' "${TESTS[@]}")" || status=1

step "done: $([ $status = 0 ] && echo PASSED || echo FAILED)"
exit $status
