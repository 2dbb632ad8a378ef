"""The EPPF descriptor as a scikit-learn transformer."""

import math
import numbers

import numpy as np
from sklearn.utils.validation import check_is_fitted

from ..utils import check_n_jobs, object_seeds
from ..utils._param_validation import Interval, IntTuple, Satisfies, StrOptions
from ..utils._simd import register_kernel
from ._base import N_JOBS, NORMAL_ORIENTATION, RANDOM_STATE, VERBOSE, PointCloudDescriptor
from . import _eppf_fast
from ._eppf_fast import MAX_GRID_SIZE, MAX_N_BINS, MAX_N_PAIRS, MIN_GRID_SIZE, MIN_N_BINS, eppf_counts

__all__ = ["EPPFTransformer", "FUNCTIONS"]

#: Names of the four point-pair functions, in histogram order.
FUNCTIONS = ("distance", "angle", "normal", "occupancy")
_SHORT = {"distance": "d", "angle": "a", "normal": "n", "occupancy": "o"}
_SCALINGS = ("fit", "object", "none")
_F1_MAX = float(np.sqrt(3.0))


def _is_function_list(value):
    """A function name, or a non-empty sequence of distinct names from FUNCTIONS."""
    names = (value,) if isinstance(value, str) else tuple(value)
    return bool(names) and len(set(names)) == len(names) and all(isinstance(f, str) and f in FUNCTIONS for f in names)


class EPPFTransformer(PointCloudDescriptor):
    """Enhanced Point Pair Functions (EPPF) descriptor of point clouds.

    For every object, ``n_pairs`` ordered point pairs are drawn at random and
    four point-pair functions are evaluated on each: the Euclidean distance
    f1, the maximum angle between the connecting line and the two tangent
    planes f2, the angle between the two normals f3 and the ratio of occupied
    voxels on the line between the points f4. Their joint 4D histogram is
    weighted by ``ln(i / N1 + c)`` along the distance axis and normalized.

    Parameters
    ----------
    n_bins : tuple of 4 ints, default=(20, 4, 5, 3)
        Bins of f1 (distance), f2 (angle), f3 (normal) and f4 (occupancy).
        ``(15, 3, 4, 3)`` is the paper's "EPPF short" (540 bins).
    n_pairs : int, default=20000
        Random ordered point pairs per object.
    c : float, default=1.2
        Constant of the distance weighting ``ln(i / n_bins[0] + c)``, with
        ``i`` the 0-based distance bin; must exceed 1 so every weight is
        positive.
    grid_size : int, default=64
        Voxels per side of the per-object occupancy grid used by f4.
    functions : tuple of str, default=("distance", "angle", "normal", "occupancy")
        Which point-pair functions make up the histogram; the others are left
        out (the paper's ablation). The histogram keeps the order of
        :data:`FUNCTIONS`.
    scaling : {"fit", "object", "none"}, default="fit"
        ``"fit"``: one data-set scale learned in :meth:`fit`, so that the
        largest training object fits a unit cube (the paper's scale-variant
        descriptor). ``"object"``: each object scaled into a unit cube
        (scale-invariant; use it for data in mixed units such as raw CAD
        files). ``"none"``: coordinates used as given (they should already lie
        in a unit cube). f1 is binned on ``[0, sqrt(3)]``; longer distances
        fall in the last bin. Any finite magnitude is accepted: a cloud whose
        largest side is below ``2**-100`` or whose coordinates exceed
        ``2**100`` is first rescaled by an exact power of two (and f1's scale
        by its inverse); with ``"fit"``, a largest training side whose inverse
        is not a finite positive float64 is a ``ValueError``.
    n_neighbors : int, default=20
        Neighbors for PCA normal estimation of clouds given without normals
        (see :func:`eppf.preprocessing.estimate_normals`). Clouds of shape (n, 6) carry their
        own normals and are not re-estimated. The default is a measured
        choice (see :ref:`api-figures-eppf-neighbors` in the documentation).
    normal_orientation : {"centroid", "origin"} or None, default="centroid"
        How estimated normals are oriented: away from the object's centroid,
        towards the origin (a sensor at the origin), or not at all.
    random_state : int, RandomState instance or None, default=None
        Seeds the pair sampling: one seed per object is drawn from it, so the
        descriptor of an object does not depend on the number of threads.
        Pass an int for reproducible output.
    n_jobs : int, default=None
        Threads for the compiled kernel and normal estimation. ``None`` uses
        the OpenMP default, which honours ``OMP_NUM_THREADS`` and
        ``threadpoolctl`` limits; ``-1`` uses all cores.
    verbose : int, default=0
        Show a progress bar over objects when positive.

    Attributes
    ----------
    n_bins_ : tuple of int
        Validated bin counts of the four functions.
    functions_ : tuple of str
        Validated function names, in histogram order.
    histogram_shape_ : tuple of int
        Shape of one descriptor viewed as a histogram (the bins of the used
        functions).
    scale_ : float or None
        With ``scaling="fit"``, the factor applied to all coordinates
        (1 / the largest bounding-box side seen in ``fit``); otherwise None.
    n_features_out_ : int
        Length of one descriptor.

    See Also
    --------
    KLNearestNeighbors : Retrieval and classification of EPPF descriptors.
    estimate_normals : PCA normals for clouds without normals.

    Notes
    -----
    For a pair ``(p1, n1), (p2, n2)`` with ``d = p2 - p1``:

    - ``f1 = |d|`` on ``[0, sqrt(3)]``;
    - ``f2 = max(beta1, beta2)``, ``beta_k = arccos(n_k . d / |d|) - pi/2``
      on ``[-pi/2, pi/2]``;
    - ``f3 = arccos(|n1 . n2|)`` on ``[0, pi/2]`` (the paper prints
      ``[0, pi]``, which the absolute value makes half empty);
    - ``f4 = N_occ / N_total`` on ``(0, 1]``: voxels hit by the integer 3D
      line between the points' voxels (both ends counted).

    A value ``v`` on ``[lo, hi]`` falls in bin
    ``clip(floor(N (v - lo) / (hi - lo)), 0, N - 1)``. The histogram is laid
    out in C order over (f1, f2, f3, f4), f4 fastest. Bin ``i`` of f1
    (0-based) is multiplied by ``ln(i / N1 + c)``; the result is divided by
    its sum. Zero bins are left as they are: the floor the paper applies to
    them belongs to matching (:class:`KLNearestNeighbors` learns it).

    Pairs with ``i == j`` are never drawn, and pairs of coincident points are
    redrawn.

    References
    ----------
    .. [1] D. Bobkov, S. Chen, R. Jian, M. Z. Iqbal and E. Steinbach,
       "Noise-resistant Deep Learning for Object Classification in 3D Point
       Clouds Using a Point Pair Descriptor", IEEE Robotics and Automation
       Letters, 3(2), 2018.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf import EPPFTransformer
    >>> rng = np.random.default_rng(0)
    >>> clouds = [rng.normal(size=(200, 3)) for _ in range(3)]
    >>> X = EPPFTransformer(n_pairs=2000, random_state=0).fit_transform(clouds)
    >>> X.shape
    (3, 1200)
    >>> bool(np.allclose(X.sum(axis=1), 1.0))
    True
    """

    def __init__(
        self,
        n_bins=(20, 4, 5, 3),
        n_pairs=20000,
        c=1.2,
        grid_size=64,
        functions=FUNCTIONS,
        scaling="fit",
        n_neighbors=20,
        normal_orientation="centroid",
        random_state=None,
        n_jobs=None,
        verbose=0,
    ):
        self.n_bins = n_bins
        self.n_pairs = n_pairs
        self.c = c
        self.grid_size = grid_size
        self.functions = functions
        self.scaling = scaling
        self.n_neighbors = n_neighbors
        self.normal_orientation = normal_orientation
        self.random_state = random_state
        self.n_jobs = n_jobs
        self.verbose = verbose

    _parameter_constraints = {
        "n_bins": [IntTuple(4, MIN_N_BINS, MAX_N_BINS,
                            description=f"a tuple of 4 ints in [{MIN_N_BINS}, {MAX_N_BINS}] (bins of f1, f2, f3, f4)")],
        "n_pairs": [Interval(numbers.Integral, 1, MAX_N_PAIRS, closed="both")],
        "c": [Interval(numbers.Real, 1, None, closed="neither",
                       description="a finite float > 1 (so that ln(i/N + c) > 0)")],
        "grid_size": [Interval(numbers.Integral, MIN_GRID_SIZE, MAX_GRID_SIZE, closed="both")],
        "functions": [Satisfies(_is_function_list, f"a non-empty sequence of distinct names from {FUNCTIONS}")],
        "scaling": [StrOptions(list(_SCALINGS))],
        "n_neighbors": [Interval(numbers.Integral, 3, 10**6, closed="both")],
        "normal_orientation": NORMAL_ORIENTATION,
        "random_state": RANDOM_STATE,
        "n_jobs": N_JOBS,
        "verbose": VERBOSE,
    }

    # ---------------------------------------------------------------- sklearn
    _progress_label = "EPPF"

    def _resolve_params(self):
        functions = (self.functions,) if isinstance(self.functions, str) else tuple(self.functions)
        functions = tuple(f for f in FUNCTIONS if f in functions)
        n_bins = tuple(int(b) for b in self.n_bins)
        return n_bins, functions, check_n_jobs(self.n_jobs, owner=type(self).__name__)

    def _learn(self, clouds, params):
        n_bins, functions, _ = params
        self.n_bins_ = n_bins
        self.functions_ = functions
        self.histogram_shape_ = tuple(b for b, f in zip(n_bins, FUNCTIONS) if f in functions)
        self.scale_ = None
        if self.scaling == "fit":
            self.scale_ = self._data_set_scale(self._learned_side(clouds))

    def _data_side(self, clouds):
        with np.errstate(over="ignore"):
            return float(clouds.sides().max())

    def _n_features(self, params):
        return int(np.prod(self.histogram_shape_))

    def fit(self, X, y=None):
        """Validate the parameters and, with ``scaling="fit"``, learn the scale.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Training point clouds (with normals in columns 3-5 if available).
        y : None
            Ignored.

        Returns
        -------
        self : EPPFTransformer
            The fitted transformer.
        """
        return super().fit(X, y)

    def transform(self, X):
        """Compute the EPPF descriptor of every point cloud.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds; columns 3-5, when present, are normals (any length
            but zero; they are normalized). Clouds without normals get PCA
            normals from ``n_neighbors`` neighbors when f2 or f3 is used.

        Returns
        -------
        X_new : ndarray of shape (n_objects, `n_features_out_`)
            Descriptors, each row non-negative and summing to 1.
        """
        return super().transform(X)

    # clouds rescaled by 2**e get f1's absolute scale times 2**-e
    _compensates_scale = True

    def _per_object(self, clouds, params, exps):
        if self.scaling == "fit":
            with np.errstate(over="ignore"):  # (an object vastly larger than the training ones: top f1 bin)
                scales = np.ldexp(np.full(len(clouds), self.scale_), -exps)
        elif self.scaling == "object":
            scales = 1.0 / clouds.sides()
        else:
            with np.errstate(over="ignore"):
                scales = np.ldexp(np.ones(len(clouds)), -exps)
        # Seeds are drawn once for the whole input, so chunking never changes a result.
        return scales, object_seeds(self.random_state, len(clouds))

    def _describe(self, clouds, params, scales, seeds, *, first_index):
        """Descriptors of one chunk of packed clouds with given scales and seeds."""
        n_threads = params[2]
        if "angle" in self.functions_ or "normal" in self.functions_:
            points, normals, offsets = self._points_and_normals(
                clouds, self.n_neighbors, self.normal_orientation, n_threads)
        else:  # (the kernel reads no normals)
            points, offsets = clouds.points, clouds.offsets
            normals = np.zeros_like(points)
        kernel_bins = tuple(b if f in self.functions_ else 1 for b, f in zip(self.n_bins_, FUNCTIONS))
        counts, status = eppf_counts(
            points, normals, offsets, scales, seeds, int(self.n_pairs), kernel_bins,
            int(self.grid_size), _F1_MAX, n_threads,
        )
        self._raise_for_status(status, first_index, {
            1: f"has too few distinct points to draw {self.n_pairs} pairs (almost all of its points coincide)"})
        return _weight_and_normalise(counts, kernel_bins, self.c, "distance" in self.functions_)

    def _feature_names(self):
        """Names of the descriptor bins, e.g. ``eppf_d03_a1_n2_o0``."""
        used = [f for f in FUNCTIONS if f in self.functions_]
        widths = [len(str(b - 1)) for b in self.histogram_shape_]
        names = []
        for idx in np.ndindex(*self.histogram_shape_):
            parts = [f"{_SHORT[f]}{i:0{w}d}" for f, i, w in zip(used, idx, widths)]
            names.append("eppf_" + "_".join(parts))
        return names

    def to_histogram(self, X):
        """View descriptors as histograms of shape ``histogram_shape_``.

        Parameters
        ----------
        X : array-like of shape (n_objects, `n_features_out_`) or (`n_features_out_`,)
            Descriptors made by this transformer.

        Returns
        -------
        H : ndarray of shape ``(n_objects, *histogram_shape_)`` or ``histogram_shape_``
            The same values, reshaped (a view when possible).
        """
        check_is_fitted(self, "n_bins_")
        X = np.asarray(X)
        if X.shape[-1] != self.n_features_out_ or X.ndim not in (1, 2):
            raise ValueError(
                f"{type(self).__name__}: descriptors must have {self.n_features_out_} values in the last axis "
                f"(histogram {self.histogram_shape_}), got shape {X.shape}"
            )
        return X.reshape(X.shape[:-1] + self.histogram_shape_)

def _weight_and_normalise(counts, kernel_bins, c, weighted):
    """Apply ``ln(i / N1 + c)`` along f1 and L1-normalize each row."""
    hist = counts.astype(np.float64).reshape((counts.shape[0],) + tuple(kernel_bins))
    if weighted:
        n1 = kernel_bins[0]
        # the C library's log, value by value: NumPy's vector log differs from it in the
        # last bit for some arguments on AVX-512 CPUs (and not on others), and these
        # weights are in every descriptor's bits
        alpha = np.array([math.log(i / n1 + c) for i in range(n1)], dtype=np.float64)
        hist *= alpha[None, :, None, None, None]
    out = hist.reshape(counts.shape[0], -1)
    out /= out.sum(axis=1, keepdims=True)
    return out


# the SIMD code this module's kernel runs, for eppf.simd_levels()
register_kernel("eppf", lambda: ("scalar", "avx2", "avx512-grouped", "avx512-skipping")[_eppf_fast._simd_level()])
