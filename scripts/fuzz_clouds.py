"""Fuzz the descriptor transformers and estimate_normals with adversarial point clouds.

Builds a fixed-seed set of adversarial clouds (magnitudes from 1e-320 to
1e308, mixed magnitudes in one cloud, far from the origin, duplicated,
collinear, planar and 1-3 point clouds, integer and float16/float32 input,
NaN/inf entries, with and without normals, including zero, huge and
subnormal normals) and runs EPPFTransformer, ESFTransformer,
WahlTransformer, OURCVFHTransformer and estimate_normals on each in a forked
child process (address space limited, a timeout per case). Every outcome is
classified as

- ``ok``: finite output, every descriptor row summing to 1 (normals of unit
  length);
- ``clean``: a ValueError or TypeError whose message names the estimator;
- ``FAIL``: a signal (segmentation fault, abort), a hang, another exception
  type, an error message that does not name the estimator, or NaN/inf (or
  rows not summing to 1) in the output.

A table of the counts is printed; the exit status is 1 when anything
failed. Case ``i`` is reproducible on its own: ``--case i`` runs it alone
and prints every outcome in full.

Usage::

    python scripts/fuzz_clouds.py            # 10,000 cases
    python scripts/fuzz_clouds.py --short    # a few hundred, seconds
    python scripts/fuzz_clouds.py --case 123 # one case, verbose

Run it from the repository root (so that the ``eppf`` of the working tree is
imported). Under the address-sanitizer build (see ``setup.py``) any
out-of-bounds access aborts the child and shows up as a FAIL with its
report on stderr; there the address-space limit is left to
``ASAN_OPTIONS=hard_rss_limit_mb=4096`` (ASan's shadow memory needs far more
address space than 4 GiB)::

    LD_PRELOAD=$(gcc -print-file-name=libasan.so) \\
    ASAN_OPTIONS=detect_leaks=0:hard_rss_limit_mb=4096 \\
    UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 python scripts/fuzz_clouds.py --short
"""

import argparse
import faulthandler
import json
import os
import resource
import select
import signal
import sys
import time
import traceback
import warnings

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402

# the four with randomised parameters below, then every other registered descriptor with its defaults
_TUNED = ("EPPFTransformer", "ESFTransformer", "WahlTransformer", "OURCVFHTransformer")


def _registered():
    from eppf.registry import DESCRIPTORS

    names = []
    for spec in DESCRIPTORS.values():
        cls = spec.cls.split(":")[1]
        if cls not in _TUNED and cls not in names:
            names.append(cls)
    return tuple(names)


ESTIMATORS = _TUNED + _registered() + ("estimate_normals",)
KINDS = (
    "sphere", "gauss", "plane", "line", "duplicates", "few", "mixed", "offset", "lattice", "clustered",
)
MAGNITUDES = (
    5e-324, 1e-320, 1e-310, 1e-307, 2.0**-1000, 1e-200, 1e-155, 1e-100, 2.0**-100, 1e-30, 1e-8, 1.0, 3.0,
    1e8, 2.0**100, 1e100, 1e155, 1e200, 1e300, 1e307, 1e308, 1.7e308,
)
MEMORY_LIMIT = 4 << 30


# --------------------------------------------------------------------- clouds
def _base(rng, kind, n):
    """A cloud of about unit size of the given kind, float64 (n, 3)."""
    if kind == "sphere":
        p = rng.normal(size=(n, 3))
        return p / np.maximum(np.linalg.norm(p, axis=1), 1e-300)[:, None]
    if kind == "gauss":
        return rng.normal(size=(n, 3))
    if kind == "plane":
        p = rng.uniform(-1, 1, size=(n, 3))
        p[:, rng.integers(3)] = 0.0
        return p
    if kind == "line":
        return rng.uniform(-1, 1, size=(n, 1)) * rng.normal(size=(1, 3))
    if kind == "duplicates":
        distinct = rng.normal(size=(int(rng.integers(1, 4)), 3))
        return distinct[rng.integers(0, len(distinct), size=n)]
    if kind == "few":
        return rng.normal(size=(int(rng.integers(1, 4)), 3))
    if kind == "lattice":
        return rng.integers(-3, 4, size=(n, 3)).astype(np.float64)
    if kind == "clustered":
        p = rng.normal(size=(n, 3)) * 1e-9
        p[: n // 2] += 1.0
        return p
    return rng.normal(size=(n, 3))  # "mixed" and "offset" start from a blob


def make_case(seed, i):
    """Case ``i``: ``(clouds, description)``; clouds is a list of arrays."""
    rng = np.random.default_rng([seed, i])
    kind = KINDS[i % len(KINDS)]
    n = int(rng.choice([1, 2, 3, 4, 5, 8, 20, 60, 150]))
    p = _base(rng, kind, n)
    dtype = str(rng.choice(["float64"] * 6 + ["float32", "float16", "int64", "int32"]))
    # magnitudes each dtype can hold (some beyond, to overflow float16/float32 to inf)
    mags = {
        "float64": MAGNITUDES,
        "float32": (1e-45, 1e-40, 1e-30, 1e-8, 1.0, 1e8, 1e30, 3e38),
        "float16": (1e-7, 1e-3, 1.0, 100.0, 6e4),
        "int64": (1.0, 100.0, 1e6, 1e15, 4e18),
        "int32": (1.0, 100.0, 1e6, 2e9),
    }[dtype]
    mag = float(rng.choice(mags))
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        if kind == "mixed":  # magnitudes spread over the whole range within one cloud
            spread = np.asarray(mags)[rng.integers(0, len(mags), size=len(p))]
            p = p * spread[:, None]
        elif kind == "offset":  # a small object far from the origin
            p = p * mag * float(rng.choice([1e-3, 1e-12])) + mag * rng.choice([-1.0, 1.0], size=3)
        else:
            p = p * mag
        # keep what overflowed as the largest finite values (inf is tested separately)
        p = np.clip(np.nan_to_num(p, nan=0.0), -np.finfo(np.float64).max, np.finfo(np.float64).max)
    desc = f"case {i}: {kind}, n={len(p)}, magnitude {mag:.3g}"
    roll = rng.uniform()
    if roll < 0.04:
        p[rng.integers(len(p)), rng.integers(3)] = rng.choice([np.nan, np.inf, -np.inf])
        desc += ", a non-finite value"
    normals = rng.uniform()
    if normals < 0.4:
        nrm = rng.normal(size=p.shape)
        style = str(rng.choice(["unit", "unit", "huge", "huge", "subnormal", "mixed", "tiny", "zero"]))
        with np.errstate(over="ignore", under="ignore"):
            if style == "zero":
                nrm[rng.integers(len(nrm))] = 0.0
            elif style == "huge":
                nrm = nrm * float(rng.choice([1e154, 1e200, 1e300, 1e308]))
            elif style == "subnormal":
                nrm = nrm * float(rng.choice([1e-310, 5e-324, 1e-300]))
            elif style == "mixed":
                nrm = nrm * np.asarray([1e-5, 1.0, 1e300])[rng.integers(0, 3, size=(len(nrm), 1))]
            elif style == "tiny":
                nrm = nrm * float(rng.choice([1e-11, 1e-13]))
            nrm = np.clip(nrm, -np.finfo(np.float64).max, np.finfo(np.float64).max)
        p = np.hstack([p, nrm])
        desc += f", {style} normals"
    if dtype != "float64":
        with np.errstate(over="ignore", invalid="ignore"):
            if dtype.startswith("int"):
                info = np.iinfo(dtype)
                p = np.clip(np.rint(p), info.min, info.max)
            p = p.astype(dtype)
        desc += f", {dtype}"
    if rng.uniform() < 0.3:
        sane = rng.normal(size=(50, p.shape[1])).astype(p.dtype)
        clouds = [sane, p] if rng.uniform() < 0.5 else [p, sane]
        desc += ", in a batch of two"
    else:
        clouds = [p]
    return clouds, desc, rng


def _estimator(name, rng):
    import eppf

    if name == "EPPFTransformer":
        return eppf.EPPFTransformer(
            n_pairs=200, scaling=str(rng.choice(["fit", "object", "none"])),
            grid_size=int(rng.choice([2, 7, 64, 100])), n_neighbors=int(rng.choice([3, 10])),
            normal_orientation=rng.choice(["centroid", "origin", None]), random_state=0, n_jobs=1,
        )
    if name == "ESFTransformer":
        return eppf.ESFTransformer(n_triplets=200, grid_size=int(rng.choice([4, 30, 64, 80])), random_state=0, n_jobs=1)
    if name == "WahlTransformer":
        return eppf.WahlTransformer(
            n_pairs=200, source=str(rng.choice(["perpendicular", "parallel"])), random_state=0, n_jobs=1
        )
    if name == "OURCVFHTransformer":
        return eppf.OURCVFHTransformer(
            scaling=str(rng.choice(["object", "object", "fit", "none"])), min_points=5,
            aggregate=str(rng.choice(["largest", "mean"])),
        )
    from eppf.registry import DESCRIPTORS

    spec = next(s for s in DESCRIPTORS.values() if s.cls.endswith(":" + name))
    return spec.make(n_samples=200, random_state=0, n_jobs=1)


def run_one(name, clouds, rng):
    """Outcome of one estimator on one case: (status, detail)."""
    import eppf

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if name == "estimate_normals":
                cloud = clouds[-1]
                cloud = cloud[:, :3] if cloud.ndim == 2 and cloud.shape[1] == 6 else cloud
                orient = [None, "centroid", "origin", [0.0, 0.0, 1e300], [1e-300, 0.0, 0.0]][int(rng.integers(5))]
                out = eppf.estimate_normals(cloud, int(rng.choice([3, 10])), orientation=orient, n_jobs=1)
                if not np.isfinite(out).all():
                    return "FAIL", "non-finite normals"
                if not np.allclose(np.linalg.norm(out, axis=1), 1.0, atol=1e-9):
                    return "FAIL", "normals not of unit length"
                return "ok", ""
            est = _estimator(name, rng)
            out = est.fit_transform(clouds)
    except (ValueError, TypeError) as exc:
        if name in str(exc):
            return "clean", f"{type(exc).__name__}: {exc}"
        return "FAIL", f"{type(exc).__name__} without the estimator's name: {exc}"
    except MemoryError:
        return "FAIL", "MemoryError (more than the address-space limit)"
    except Exception as exc:
        return "FAIL", "".join(traceback.format_exception_only(type(exc), exc)).strip()
    out = np.asarray(out)
    if out.shape[0] != len(clouds) or not np.isfinite(out).all():
        return "FAIL", f"non-finite or misshaped output {out.shape}"
    if (out < 0).any():
        return "FAIL", "negative histogram values"
    # EPPF, ESF, Wahl and OUR-CVFH (normalize=True) are distributions; PCL's VFH/GASD/CVFH/GRSD
    # scalings (percentages, counts) are only checked for finite, non-negative values
    if name in _TUNED and not np.allclose(out.sum(axis=1), 1.0, rtol=0, atol=1e-9):
        return "FAIL", f"rows sum to {out.sum(axis=1)}"
    return "ok", ""


# ---------------------------------------------------------------- the runner
def _sanitized():
    """Whether AddressSanitizer's runtime is loaded (it reserves terabytes of
    address space for its shadow memory, so RLIMIT_AS cannot be used; set
    ``hard_rss_limit_mb`` in ASAN_OPTIONS instead)."""
    try:
        with open("/proc/self/maps") as fh:
            return "libasan" in fh.read()
    except OSError:
        return "libasan" in os.environ.get("LD_PRELOAD", "")


def _child(seed, i, start, wfd):
    if not _sanitized():
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    clouds, _, rng = make_case(seed, i)
    # every estimator sees the same draws whether or not the earlier ones ran
    rngs = [np.random.default_rng([seed, i, j]) for j in range(len(ESTIMATORS))]
    del rng
    with os.fdopen(wfd, "w", buffering=1) as pipe:
        for j in range(start, len(ESTIMATORS)):
            pipe.write(json.dumps({"start": j}) + "\n")
            status, detail = run_one(ESTIMATORS[j], clouds, rngs[j])
            pipe.write(json.dumps({"done": j, "status": status, "detail": detail[:500]}) + "\n")
    os._exit(0)


def run_case(seed, i, timeout):
    """Outcomes of every estimator on case ``i`` (a list of (status, detail))."""
    results = [None] * len(ESTIMATORS)
    start = 0
    while start < len(ESTIMATORS):
        rfd, wfd = os.pipe()
        pid = os.fork()
        if pid == 0:
            os.close(rfd)
            faulthandler.disable()  # a crash is reported by the parent, not by a traceback
            try:
                _child(seed, i, start, wfd)
            finally:
                os._exit(3)
        os.close(wfd)
        current, buf, hung = start, b"", False
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                hung = True
                break
            ready, _, _ = select.select([rfd], [], [], left)
            if not ready:
                continue
            chunk = os.read(rfd, 65536)
            if not chunk:
                break
            buf += chunk
            *lines, buf = buf.split(b"\n")
            for line in lines:
                msg = json.loads(line)
                if "start" in msg:
                    current = msg["start"]
                    deadline = time.monotonic() + timeout
                else:
                    results[msg["done"]] = (msg["status"], msg["detail"])
                    current = msg["done"] + 1
        os.close(rfd)
        if hung:
            os.kill(pid, signal.SIGKILL)
        _, status = os.waitpid(pid, 0)
        if current >= len(ESTIMATORS):
            break
        if hung:
            results[current] = ("FAIL", f"hang (no result within {timeout:g} s)")
        elif os.WIFSIGNALED(status):
            sig = os.WTERMSIG(status)
            results[current] = ("FAIL", f"killed by signal {sig} ({signal.Signals(sig).name})")
        elif results[current] is None:
            results[current] = ("FAIL", f"child exited with status {os.WEXITSTATUS(status)}")
        start = current + 1
    return results


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n-cases", type=int, default=10_000, help="number of cases (default 10,000)")
    parser.add_argument("--short", action="store_true", help="a few hundred cases (for the test suite)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the case generator (default 0)")
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds allowed per estimator call")
    parser.add_argument("--case", type=int, default=None, help="run this case alone and print its outcomes")
    args = parser.parse_args(argv)
    import eppf  # noqa: F401  (imported once here, so children fork with it loaded)

    if args.case is not None:
        _, desc, _ = make_case(args.seed, args.case)
        print(desc)
        for name, (status, detail) in zip(ESTIMATORS, run_case(args.seed, args.case, args.timeout)):
            print(f"  {name:20s} {status:6s} {detail}")
        return 0
    n_cases = 200 if args.short else args.n_cases
    counts = {name: {"ok": 0, "clean": 0, "FAIL": 0} for name in ESTIMATORS}
    failures = []
    t0 = time.monotonic()
    for i in range(n_cases):
        for name, (status, detail) in zip(ESTIMATORS, run_case(args.seed, i, args.timeout)):
            counts[name][status] += 1
            if status == "FAIL":
                failures.append((i, name, detail))
    elapsed = time.monotonic() - t0
    print(f"{n_cases} adversarial clouds (seed {args.seed}), {elapsed:.1f} s")
    print(f"{'estimator':22s}{'ok':>8s}{'clean':>8s}{'FAIL':>8s}")
    for name in ESTIMATORS:
        c = counts[name]
        print(f"{name:22s}{c['ok']:8d}{c['clean']:8d}{c['FAIL']:8d}")
    for i, name, detail in failures[:30]:
        print(f"FAIL {name} on {make_case(args.seed, i)[1]}: {detail}")
    if len(failures) > 30:
        print(f"... and {len(failures) - 30} more failures")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
