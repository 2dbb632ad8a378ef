"""Recall and speed of approximate symmetric-KL retrieval (ApproximateKLNearestNeighbors).

Usage::

    nice -n 10 python benchmarks/bench_ann.py --data-dir DIR --cache eppf_real.npz
    nice -n 10 python benchmarks/bench_ann.py --data-dir DIR --cache eppf_real.npz --n-database 100000

Two measurements, both against exact symmetric KL search
(:func:`eppf.symmetric_kl_distances` / :class:`eppf.KLNearestNeighbors`,
same floor):

1. **Real descriptors**: EPPF descriptors (``EPPFTransformer(random_state=0)``)
   of every object of ``modelnet10_1024.npz`` and ``dales_objects.npz``
   (``--data-dir`` or ``$EPPF_BENCH_DATA``; 5,398 objects). Leave-one-out
   retrieval over all of them: recall@1 of the approximate search against
   the exact leave-one-out neighbour, and queries per second.
2. **Synthetic database** of ``--n-database`` rows (default 1,000,000) made
   around the real descriptors: each row mixes two random real descriptors,
   ``(1 - t) a + t b`` with ``t ~ U(0, 0.3)``, multiplies every bin by
   independent log-normal noise ``exp(0.5 g)``, ``g ~ N(0, 1)``, and is
   renormalised; it keeps the sparsity of EPPF histograms (about 4 % of bins
   non-empty). ``--n-queries`` fresh rows from the same generator (not in
   the database) are the queries; their exact nearest neighbours are found
   by :func:`eppf.symmetric_kl_distances` over database blocks. Reported:
   index build time (:meth:`fit`), index memory (the serialised faiss
   index), queries per second of ``kneighbors(n_neighbors=1)``, recall@1.

Queries per second are wall-clock figures with ``--threads`` threads;
queries per CPU second (user + system time of all threads) are what one
uncontended core delivers, the steadier figure on a shared machine.
recall@1 counts a query as found when the returned neighbour's exact
distance equals the exact nearest distance (up to 1e-9 relative, so an
exact duplicate of the true neighbour counts); the share of identical
indices is printed too. The database is float32 (1,000,000 x 1,200 is
4.8 GB); peak memory of the whole run is about twice that, so use
``--n-database`` for a smaller run first. ``--cache FILE`` keeps the real
descriptors between runs (about 1 minute per run otherwise on 2 cores).

Figures (2-vCPU Intel Xeon KVM guest, quiet: load average 1.4 to 1.7; 2
threads; ``n_candidates=32, n_components=32``; ``--index ivf --n-probe 48
64 96 128``; the full table is in docs/performance.rst, "Approximate
retrieval")::

    real       ivf  n_probe=48     n=5,398      recall@1 1.000  7768 q/s         build   1 s  index   1 MiB
    synthetic  ivf  n_probe=48     n=1,000,000  recall@1 0.980  3210 q/s (1829/CPU s)  build  42 s  index 130 MiB
    synthetic  ivf  n_probe=64     n=1,000,000  recall@1 0.988  2862 q/s (1620/CPU s)  build  42 s  index 130 MiB
    synthetic  ivf  n_probe=96     n=1,000,000  recall@1 0.994  2117 q/s (1193/CPU s)  build  42 s  index 130 MiB
    synthetic  ivf  n_probe=128    n=1,000,000  recall@1 0.998  1657 q/s  (948/CPU s)  build  42 s  index 130 MiB

Exact search over the million: 5 queries per second (2 to 3 under load).
n_probe=128 is the estimator's default.
"""

import argparse
import json
import os
import resource
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from _data import default_dir, in_dir  # noqa: E402

PROG = "bench_ann.py"
SETS = ("modelnet10_1024", "dales_objects")


def real_descriptors(data_dir, cache, n_jobs):
    """EPPF descriptors (float32) and labels of every object of the two data sets."""
    if cache and os.path.isfile(cache):
        with np.load(cache) as f:
            return f["X"], f["y"]
    from eppf import EPPFTransformer

    Xs, ys, offset = [], [], 0
    for name in SETS:
        with np.load(in_dir(PROG, data_dir, name)) as f:
            pts, off, labels = f["points"], f["offsets"], f["labels"]
        clouds = [pts[off[i] : off[i + 1]] for i in range(len(off) - 1)]
        t = time.perf_counter()
        Xs.append(EPPFTransformer(random_state=0, n_jobs=n_jobs).fit_transform(clouds).astype(np.float32))
        ys.append(labels + offset)
        offset += int(labels.max()) + 1
        print(f"EPPF of {name}: {len(clouds)} objects in {time.perf_counter() - t:.1f} s", flush=True)
    X, y = np.vstack(Xs), np.concatenate(ys)
    if cache:
        np.savez(cache, X=X, y=y)
    return X, y


def synthetic(seeds, n, rng, out=None, block=20000):
    """``n`` float32 histograms around ``seeds``: two-seed mixtures with log-normal noise per bin."""
    out = np.empty((n, seeds.shape[1]), dtype=np.float32) if out is None else out
    for start in range(0, n, block):
        m = min(block, n - start)
        a = seeds[rng.integers(len(seeds), size=m)]
        b = seeds[rng.integers(len(seeds), size=m)]
        t = rng.uniform(0.0, 0.3, size=(m, 1)).astype(np.float32)
        h = (1 - t) * a + t * b
        h *= np.exp(0.5 * rng.standard_normal(h.shape, dtype=np.float32))
        h /= h.sum(axis=1, keepdims=True)
        out[start : start + m] = h
    return out


def exact_nearest(Q, X, floor, n_jobs, block=20000):
    """Exact 1-NN (index, distance) of each query over ``X``, ties to the lowest index."""
    from eppf import symmetric_kl_distances

    best_d = np.full(len(Q), np.inf)
    best_i = np.full(len(Q), -1, dtype=np.intp)
    for start in range(0, len(X), block):
        D = symmetric_kl_distances(Q, X[start : start + block], floor=floor, n_jobs=n_jobs)
        i = np.argmin(D, axis=1)
        d = D[np.arange(len(Q)), i]
        better = d < best_d
        best_d[better], best_i[better] = d[better], i[better] + start
    return best_i, best_d


def recall(ind, dist, exact_ind, exact_dist):
    hit = dist <= exact_dist * (1 + 1e-9) + 1e-12
    return float(np.mean(hit)), float(np.mean(ind == exact_ind))


def cpu_s():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def peak_mib():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def make_ann(args, index):
    from eppf.neighbors import ApproximateKLNearestNeighbors

    return ApproximateKLNearestNeighbors(n_candidates=args.n_candidates, n_components=args.n_components,
                                         index=index, n_probe=args.n_probe[0], ef_search=args.ef_search[0],
                                         random_state=0, n_jobs=args.threads)


def index_mib(ann):
    import faiss

    return faiss.serialize_index(ann.index_).nbytes / 2**20


def bench_real(X, y, args):
    from eppf import KLNearestNeighbors

    exact = KLNearestNeighbors(n_jobs=args.threads).fit(X, y)
    t = time.perf_counter()
    e_dist, e_ind = exact.kneighbors(n_neighbors=1)
    t_exact = time.perf_counter() - t
    out = []
    for index in args.index:
        t = time.perf_counter()
        ann = make_ann(args, index).fit(X, y)
        t_fit = time.perf_counter() - t
        t, c = time.perf_counter(), cpu_s()
        dist, ind = ann.kneighbors(n_neighbors=1)
        t_q, c_q = time.perf_counter() - t, cpu_s() - c
        r, same = recall(ind[:, 0], dist[:, 0], e_ind[:, 0], e_dist[:, 0])
        out.append({"part": "real", "index": index, "n_database": len(X), "n_queries": len(X), "build_s": t_fit,
                    "index_mib": index_mib(ann), "qps": len(X) / t_q, "queries_per_cpu_s": len(X) / c_q,
                    "exact_qps": len(X) / t_exact,
                    "recall_at_1": r, "same_index": same,
                    "loo_accuracy_ann": float(np.mean(y[ind[:, 0]] == y)),
                    "loo_accuracy_exact": float(np.mean(y[e_ind[:, 0]] == y))})
        print(json.dumps(out[-1]), flush=True)
    return out


def bench_synthetic(seeds, args):
    rng = np.random.default_rng(args.seed)
    t = time.perf_counter()
    db = synthetic(seeds, args.n_database, rng)
    Q = synthetic(seeds, args.n_queries, np.random.default_rng(args.seed + 1))
    t_gen = time.perf_counter() - t
    print(f"generated {args.n_database:,} + {args.n_queries:,} histograms in {t_gen:.1f} s", flush=True)
    labels = np.zeros(len(db), dtype=np.int8)
    runs = []
    for index in args.index:
        t = time.perf_counter()
        ann = make_ann(args, index).fit(db, labels)
        t_fit = time.perf_counter() - t
        print(f"{index} index built in {t_fit:.1f} s", flush=True)
        ann.kneighbors(Q[:50], n_neighbors=1)  # warm-up
        knob = "n_probe" if index == "ivf" else "ef_search"
        for value in getattr(args, knob):  # a sweep of the query-time knob on the same index
            ann.set_params(**{knob: value})
            t, c = time.perf_counter(), cpu_s()
            dist, ind = ann.kneighbors(Q, n_neighbors=1)
            t_q, c_q = time.perf_counter() - t, cpu_s() - c
            label = f"{index} {knob}={value}"
            print(f"{label}: {len(Q) / t_q:.0f} queries/s, {len(Q) / c_q:.0f} per CPU second", flush=True)
            runs.append((label, t_fit, index_mib(ann), t_q, c_q, dist[:, 0], ind[:, 0], ann.floor_))
        del ann
    n_exact = min(args.n_exact, len(Q))
    t = time.perf_counter()
    e_ind, e_dist = exact_nearest(Q[:n_exact], db, runs[0][7], args.threads)
    t_exact = time.perf_counter() - t
    out = []
    for index, t_fit, mib, t_q, c_q, dist, ind, _ in runs:
        r, same = recall(ind[:n_exact], dist[:n_exact], e_ind, e_dist)
        out.append({"part": "synthetic", "index": index, "n_database": len(db), "n_queries": len(Q),
                    "n_exact": n_exact, "build_s": t_fit, "index_mib": mib, "database_mib": db.nbytes / 2**20,
                    "qps": len(Q) / t_q, "queries_per_cpu_s": len(Q) / c_q, "exact_qps": n_exact / t_exact,
                    "recall_at_1": r, "same_index": same,
                    "peak_mib": peak_mib()})
        print(json.dumps(out[-1]), flush=True)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data-dir", default=default_dir(), help="folder of the .npz data sets (default $EPPF_BENCH_DATA)")
    ap.add_argument("--cache", default=None, help="npz file keeping the real EPPF descriptors between runs")
    ap.add_argument("--n-database", type=int, default=1_000_000)
    ap.add_argument("--n-queries", type=int, default=2000, help="queries timed on the synthetic database")
    ap.add_argument("--n-exact", type=int, default=500, help="of them, with exact ground truth")
    ap.add_argument("--n-candidates", type=int, default=32)
    ap.add_argument("--n-components", type=int, default=32)
    ap.add_argument("--n-probe", type=int, nargs="+", default=[128],
                    help="lists scanned per query (several: a sweep on the same index, synthetic part)")
    ap.add_argument("--ef-search", type=int, nargs="+", default=[64], help="the same for the HNSW graph")
    ap.add_argument("--index", nargs="+", default=["ivf", "hnsw"], choices=["ivf", "hnsw"])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--skip-real", action="store_true")
    ap.add_argument("--skip-synthetic", action="store_true")
    args = ap.parse_args(argv)
    os.environ.setdefault("OMP_NUM_THREADS", str(args.threads))
    X, y = real_descriptors(args.data_dir, args.cache, args.threads)
    results = []
    if not args.skip_real:
        results += bench_real(X, y, args)
    if not args.skip_synthetic:
        results += bench_synthetic(X, args)
    print(f"\nparameters: n_candidates={args.n_candidates} n_components={args.n_components} "
          f"threads={args.threads}; peak {peak_mib():.0f} MiB")
    for r in results:
        print(f"{r['part']:9s} {r['index']:18s} n={r['n_database']:>9,}  recall@1={r['recall_at_1']:.4f} "
              f"(same index {r['same_index']:.4f})  {r['qps']:6.0f} queries/s, {r['queries_per_cpu_s']:6.0f} per CPU s "
              f"(exact {r['exact_qps']:.0f}/s)  "
              f"build {r['build_s']:.1f} s  index {r['index_mib']:.0f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
