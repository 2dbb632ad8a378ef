"""The base class of every point-cloud descriptor transformer.

A descriptor maps a list of point clouds (arrays of shape (n_i, 3), or (n_i, 6)
with normals in columns 3-5) to one row per object. What every descriptor does
the same way is written here once:

- parameters are checked against the class's ``_parameter_constraints``
  (:func:`eppf.utils._param_validation.validate_params`: one message style,
  naming the estimator, the parameter and what it accepts), then resolved by
  the subclass (:meth:`PointCloudDescriptor._resolve_params`);
- ``fit`` checks the clouds, lets the subclass learn from them
  (:meth:`PointCloudDescriptor._learn`, e.g. EPPF's data-set scale) and
  records ``n_features_out_``; ``partial_fit`` does the same batch by batch
  (the data-set scale from the largest side of any batch,
  :meth:`PointCloudDescriptor._learned_side`);
- a stream of clouds (:func:`eppf.describe_files`) is described chunk by
  chunk, chunks side by side, with the rows of one ``fit_transform``: the
  descriptor says whether it must see every cloud first
  (:meth:`PointCloudDescriptor._learns_from_data`) and makes the copy that
  describes the next chunk with that chunk's seeds
  (:meth:`PointCloudDescriptor._stream_part`);
- ``transform`` checks the parameters and validates the clouds once (all of
  them, in one compiled pass, into one :class:`eppf.utils.PackedClouds`),
  draws the per-object inputs (seeds from ``random_state``, scales) for the
  whole input before chunking, and hands chunks of objects (slices of the
  packed clouds, with the resolved parameters) to joblib
  (:func:`eppf.utils.transform_in_chunks`), so results never depend on threads,
  chunk sizes or where a chunk runs;
- clouds may carry extra per-point columns after the coordinates (and
  normals), such as GASD color's RGB: ``_extra_columns`` says how many, and
  :meth:`PointCloudDescriptor._check_extra_columns` checks and converts them;
  they reach ``_describe`` as its last per-object argument;
- kernel status codes become a ``ValueError`` naming the estimator and the
  object (:meth:`PointCloudDescriptor._raise_for_status`);
- the kernels' input: the packed points with their normals (estimated where
  missing, :meth:`PointCloudDescriptor._points_and_normals`), optionally
  centered and scaled per object (:meth:`PointCloudDescriptor._centred_points_and_normals`);
- tags for ragged (non-tabular) input and ``get_feature_names_out``.

A subclass declares ``_parameter_constraints`` and provides
``_resolve_params`` (resolved parameters), ``_n_features``, ``_describe`` (the
rows of one chunk of packed clouds) and ``_feature_names``, and sets
``_min_points``.

The constraint lists that several descriptors share are the module's public
constants (``NORMAL_ORIENTATION``, ``N_JOBS``, ...).
"""

import copy
import functools
import numbers

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils import check_random_state
from sklearn.utils.validation import check_is_fitted

from ..preprocessing._normal_options import N_NEIGHBORS
from ..utils import PackedClouds, check_n_jobs, check_packed_clouds, object_seeds, transform_in_chunks
from ..utils._validation import as_vector3, condition_point_clouds
from ..utils._param_validation import N_JOBS, RANDOM_STATE, Interval, Options, StrOptions, validate_params

__all__ = [
    "N_JOBS",
    "N_NEIGHBORS",
    "NORMAL_ORIENTATION",
    "RANDOM_STATE",
    "SCALING",
    "VERBOSE",
    "PointCloudDescriptor",
    "as_vector3",
]


#: ``verbose``: a non-negative int (or a bool).
VERBOSE = [Interval(numbers.Integral, 0, None, closed="left"), Options(bool)]
#: ``normal_orientation`` of estimated normals.
NORMAL_ORIENTATION = [StrOptions(["centroid", "origin"], description="'centroid', 'origin'"), None]
#: ``scaling`` of the descriptors that center each object and scale it to a unit box.
SCALING = [StrOptions(["object", "fit", "none"])]


class PointCloudDescriptor(TransformerMixin, BaseEstimator):
    """Base class of eppf's point-cloud descriptor transformers.

    Not for direct use: subclasses implement the hooks described in the
    module docstring. ``random_state``, ``n_jobs`` and ``verbose`` are read
    when a subclass has them.
    """

    #: Parameter name -> accepted values (see :mod:`eppf.utils._param_validation`).
    _parameter_constraints = {}
    #: Fewest points a cloud may have.
    _min_points = 2
    #: Label of the progress bar (``verbose``).
    _progress_label = ""
    #: Extra per-point columns after the coordinates (and normals), e.g. 3 for RGB.
    _extra_columns = 0
    #: What the extra columns hold, for messages (``"rgb"``).
    _extra_columns_name = ""

    # ----------------------------------------------------------------- hooks
    def _check_params(self):
        """Validate the parameters against ``_parameter_constraints``; return them resolved."""
        validate_params(self)
        return self._resolve_params()

    def _resolve_params(self):  # pragma: no cover - every subclass overrides it
        """The validated parameters resolved (any object the other hooks take); cross-parameter checks."""
        raise NotImplementedError

    def _n_features(self, params):  # pragma: no cover - every subclass overrides it
        """Width of the output for resolved ``params``."""
        raise NotImplementedError

    def _learn(self, clouds, params):
        """Learn from the validated training clouds (nothing by default)."""

    def _per_object(self, clouds, params, exps):
        """Per-object inputs drawn for the whole input before chunking.

        By default one seed per object when the descriptor has a
        ``random_state``, nothing otherwise. ``exps`` are the exponents of
        :meth:`_condition` (for descriptors that measure absolute lengths).
        """
        if "random_state" not in self.get_params(deep=False):
            return ()
        return (object_seeds(self.random_state, len(clouds)),)

    def _check_extra_columns(self, index, values):  # pragma: no cover - overridden where _extra_columns > 0
        """Check and convert the extra columns ``values`` (n, _extra_columns) of cloud ``index``."""
        raise NotImplementedError

    def _describe(self, clouds, params, *per_object, first_index):  # pragma: no cover - overridden
        """The rows of one chunk of packed clouds (a :class:`~eppf.utils.PackedClouds`)."""
        raise NotImplementedError

    def _feature_names(self):  # pragma: no cover - every subclass overrides it
        """One name per output column."""
        raise NotImplementedError

    # ------------------------------------------------------------- plumbing
    def _threads(self, none_means=None):
        """Threads for ``n_jobs`` (joblib's meaning); ``none_means`` overrides what None gives."""
        n_jobs = getattr(self, "n_jobs", None)
        if n_jobs is None and none_means is not None:
            return none_means
        return check_n_jobs(n_jobs, owner=type(self).__name__)

    def _validate_clouds(self, X, n_threads=1):
        """Validated clouds (a :class:`~eppf.utils.PackedClouds`), and the list of their checked extra
        columns (None without any)."""
        if not self._extra_columns:
            return check_packed_clouds(X, owner=type(self).__name__, min_points=self._min_points,
                                       n_threads=n_threads), None
        return self._split_extra_columns(X, n_threads)

    def _split_extra_columns(self, X, n_threads):
        """Split clouds of shape (n, 3 + e) or (n, 6 + e) into validated clouds and checked extras."""
        owner = type(self).__name__
        e, what = self._extra_columns, self._extra_columns_name
        if X is None or isinstance(X, (str, bytes, dict, PackedClouds)):
            raise TypeError(f"{owner}: X must be a list of (n_i, {3 + e}) or (n_i, {6 + e}) arrays "
                            f"(xyz[, normals], {what}), got {type(X).__name__}")
        try:
            items = list(X)
        except TypeError:
            raise TypeError(f"{owner}: X must be a list of point clouds, got {type(X).__name__}") from None
        if not items:
            raise ValueError(f"{owner}: X is empty: at least one point cloud is needed")
        xyz, extras = [], []
        for i, c in enumerate(items):
            try:
                a = np.asarray(c)
            except Exception as exc:
                raise TypeError(f"{owner}: point cloud {i} could not be converted to an array: {exc}") from None
            if a.dtype == object or not (np.issubdtype(a.dtype, np.number) or a.dtype == bool) or np.iscomplexobj(a):
                raise TypeError(f"{owner}: point cloud {i} must hold real numbers, got dtype {a.dtype}")
            if a.ndim != 2 or a.shape[1] not in (3 + e, 6 + e):
                raise ValueError(f"{owner}: point cloud {i} must have shape (n_points, {3 + e}) (xyz, {what}) or "
                                 f"(n_points, {6 + e}) (xyz, normals, {what}), got shape {a.shape}")
            extras.append(self._check_extra_columns(i, a[:, -e:]))
            xyz.append(a[:, :-e])
        clouds = check_packed_clouds(xyz, owner=owner, min_points=self._min_points, n_threads=n_threads)
        return clouds, extras

    def _points_and_normals(self, clouds, n_neighbors, orientation, n_threads):
        """``points``, ``normals`` (N, 3) and ``offsets`` of packed clouds for the kernels.

        Clouds given with normals keep them; the others get PCA normals from
        ``n_neighbors`` neighbors (:func:`eppf.preprocessing.estimate_normals`),
        oriented by ``orientation``. Each object's normals depend on it alone,
        so estimating them on the whole block or on the objects without
        normals gives the same values.
        """
        return points_and_normals(clouds, n_neighbors, orientation, n_threads, owner=type(self).__name__)

    def _fit_scale(self, clouds):
        """With ``scaling="fit"``, 1 / the largest bounding-box side of any cloud; else 1."""
        if self.scaling != "fit":
            return 1.0
        return self._data_set_scale(self._learned_side(clouds))

    def _data_side(self, clouds):
        """The largest bounding-box side of any of the validated clouds (inf beyond float64)."""
        return float(clouds.sides().max())

    def _learned_side(self, clouds):
        """The side the data-set scale is learnt from: the largest of ``clouds`` (fit), or of every batch so far
        (partial_fit)."""
        side = vars(self).get("_partial_fit_side")
        return self._data_side(clouds) if side is None else side

    def _data_set_scale(self, side):
        """1 / ``side``, or a ValueError when that is not a finite positive float64."""
        with np.errstate(over="ignore", divide="ignore"):
            scale = float(1.0 / side) if side > 0 else np.inf
        if not (np.isfinite(side) and np.isfinite(scale) and scale > 0):
            raise ValueError(
                f"{type(self).__name__}: the largest training object's side ({side:.3g}) is out of float64's "
                "range for one data-set scale (1 / side must be finite and non-zero); rescale the data or "
                "use scaling='object'"
            )
        return scale

    #: How clouds of extreme magnitude reach the kernels: ``"rescale"`` (an
    #: exact power-of-two rescaling, see :meth:`_condition`) or ``"none"``
    #: (the descriptor brings magnitudes into range itself).
    _conditioning = "rescale"

    def _condition(self, clouds):
        """Bring clouds of extreme magnitude into the kernels' range; return the exponents.

        A cloud whose largest side is below ``2**-100`` or whose coordinates
        exceed ``2**100`` is multiplied by an exact power of two ``2**e``
        (:func:`eppf.utils.condition_point_clouds`); the others are left bit
        for bit. That changes nothing for descriptors invariant to scale. A
        descriptor with ``scaling`` other than ``"object"`` measures lengths
        in the input's units, so such a cloud is refused there with a
        ValueError; EPPF instead takes ``2**-e`` into its f1 scale.
        """
        if self._conditioning == "none":
            return np.zeros(len(clouds), dtype=np.int64)
        owner = type(self).__name__
        exps = condition_point_clouds(clouds, owner=owner)
        scaling = self.get_params(deep=False).get("scaling", "object")
        if scaling != "object" and exps.any() and not self._compensates_scale:
            k = int(np.flatnonzero(exps)[0])
            raise ValueError(
                f"{owner}: point cloud {k} has coordinates out of the magnitude range this estimator computes in "
                f"without overflow or underflow (largest side >= 2**-100, |coordinates| <= 2**100); with "
                f"scaling={scaling!r} its lengths are taken in the input's units, so rescale the data or "
                "use scaling='object'"
            )
        return exps

    #: True for descriptors that take the conditioning's ``2**-e`` into their own scale.
    _compensates_scale = False

    def _centred_points_and_normals(self, clouds, n_neighbors, n_threads):
        """:meth:`_points_and_normals` (oriented by ``normal_orientation``), each object centered.

        Each object's points (a copy) are centered on their mean, then divided
        by their largest bounding-box side (``scaling="object"``) or
        multiplied by ``scale_`` (``scaling="fit"``).
        """
        points, normals, offsets = self._points_and_normals(clouds, n_neighbors, self.normal_orientation, n_threads)
        points = points.copy()
        for k in range(len(clouds)):
            p = points[offsets[k] : offsets[k + 1]]
            p -= p.mean(axis=0)
            if self.scaling == "object":
                p /= np.ptp(p, axis=0).max()
            elif self.scaling == "fit":
                p *= self.scale_
        return points, normals, offsets

    def _raise_for_status(self, status, first_index, messages):
        """Raise a ValueError for the first object whose kernel status is non-zero.

        ``messages`` maps a status code to what went wrong with the object
        (``"has no triangles of non-zero area"``); other codes get a generic
        message.
        """
        bad = np.flatnonzero(status)
        if bad.size:
            code = int(status[bad[0]])
            what = messages.get(code, f"could not be described (kernel status {code})")
            raise ValueError(f"{type(self).__name__}: point cloud {first_index + int(bad[0])} {what}")

    # --------------------------------------------------------------- sklearn
    def fit(self, X, y=None):
        """Check the parameters and the clouds, and learn what the descriptor needs.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Training point clouds, with normals in columns 3-5 when available.
        y : None
            Ignored.

        Returns
        -------
        self : object
            The fitted transformer.
        """
        params = self._check_params()
        clouds, _ = self._validate_clouds(X)
        vars(self).pop("_partial_fit_side", None)
        self._learn(clouds, params)
        self.n_features_out_ = int(self._n_features(params))
        return self

    def fit_transform(self, X, y=None):
        """Fit to the clouds, then compute their descriptors.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Training point clouds, with normals in columns 3-5 when
            available; an iterator (a generator) is read once.
        y : None
            Ignored.

        Returns
        -------
        X_new : ndarray of shape (n_objects, `n_features_out_`)
            The descriptors, one row per cloud, those of ``fit(X).transform(X)``.
        """
        if hasattr(X, "__next__"):  # fit would use an iterator up, leaving transform nothing
            X = list(X)
        return self.fit(X, y).transform(X)

    def partial_fit(self, X, y=None):
        """Fit on one more batch of the training clouds.

        Batches given one after another (since the last :meth:`fit`) leave
        the descriptor fitted as :meth:`fit` on all of them at once: with
        ``scaling="fit"``, the data-set scale is one over the largest
        bounding-box side of any cloud of any batch. A data set too large for
        memory can be fitted batch by batch (:func:`eppf.describe_files` does
        so for files).

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            One batch of training point clouds, with normals in columns 3-5
            when available.
        y : None
            Ignored.

        Returns
        -------
        self : object
            The fitted transformer.
        """
        params = self._check_params()
        clouds, _ = self._validate_clouds(X)
        seen = vars(self).get("_partial_fit_side")
        if self._learns_from_data():
            side = self._data_side(clouds)
            self._partial_fit_side = side if seen is None or side > seen else seen
        try:
            self._learn(clouds, params)  # the data-set scale from _learned_side: every batch's
        except BaseException:
            if seen is not None:
                self._partial_fit_side = seen
            else:
                vars(self).pop("_partial_fit_side", None)
            raise
        self.n_features_out_ = int(self._n_features(params))
        return self

    # -------------------------------------------------------------- streams
    # eppf.describe_files describes a stream of clouds chunk by chunk, with
    # rows bit for bit those of one fit_transform on all of them, through
    # these hooks (DescriptorUnion has the same).
    def _learns_from_data(self):
        """Whether fit learns from the clouds (``scaling="fit"``): every cloud must be seen before the first row."""
        return self.get_params(deep=False).get("scaling") == "fit"

    def _stream_generator(self):
        """The generator a stream of ``transform`` calls draws from, made once per stream.

        One ``transform`` over all the clouds draws its per-object seeds
        (:meth:`_per_object`) from ``check_random_state(random_state)``: a
        fresh generator for an int, which a stream keeps and goes on drawing
        from; the generator itself for a RandomState or None. None for
        descriptors without ``random_state``.
        """
        if "random_state" not in self.get_params(deep=False):
            return None
        return check_random_state(self.random_state)

    def _stream_part(self, n_objects, generator, n_jobs=None):
        """A copy of this fitted descriptor for the next ``n_objects`` clouds of a stream.

        The copy's ``transform`` of those clouds gives the rows one
        ``transform`` over the whole stream gives them, wherever and whenever
        it runs: it draws from a copy of ``generator`` in the state those
        clouds find it in, and ``generator`` moves on past their seeds (one
        per object, as :meth:`_per_object` draws them), so the next part can
        be made at once and described beside this one. ``n_jobs``, when
        given, is the copy's ``n_jobs``.
        """
        part = copy.copy(self)
        if n_jobs is not None:
            part.n_jobs = n_jobs
        if generator is not None:
            part.random_state = copy.deepcopy(generator)
            object_seeds(generator, n_objects)
        return part

    def transform(self, X):
        """Compute one descriptor row per point cloud.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds, with normals in columns 3-5 when available.

        Returns
        -------
        X_new : ndarray of shape (n_objects, `n_features_out_`)
            The descriptors, one row per cloud.
        """
        check_is_fitted(self, "n_features_out_")
        params = self._check_params()
        clouds, extras = self._validate_clouds(X, self._threads())
        exps = self._condition(clouds)
        per_object = self._per_object(clouds, params, exps)
        if extras is not None:
            holder = np.empty(len(extras), dtype=object)
            holder[:] = extras
            per_object = tuple(per_object) + (holder,)
        # The parameters travel with the chunks, checked once for the whole call.
        return transform_in_chunks(
            functools.partial(_describe_chunk, params=params), self, clouds, per_object,
            n_features=self.n_features_out_, verbose=getattr(self, "verbose", 0), desc=self._progress_label,
        )

    def get_feature_names_out(self, input_features=None):
        """Get the names of the output columns.

        Parameters
        ----------
        input_features : None
            Ignored (point clouds have no input feature names).

        Returns
        -------
        feature_names_out : ndarray of str
            One name per column, in the output's order.
        """
        check_is_fitted(self, "n_features_out_")
        return np.asarray(self._feature_names(), dtype=object)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.two_d_array = False
        tags.input_tags.three_d_array = True
        tags.requires_fit = True
        tags.non_deterministic = "random_state" in self.get_params(deep=False) and self.random_state is None
        return tags


def points_and_normals(clouds, n_neighbors, orientation, n_threads, *, owner):
    """``points``, ``normals`` (N, 3) and ``offsets`` of validated packed clouds, PCA normals where missing.

    Clouds given with normals keep them; the others get PCA normals from
    ``n_neighbors`` neighbors (:func:`eppf.preprocessing.estimate_normals`),
    oriented by ``orientation``. Each object's normals depend on it alone,
    so estimating them on the whole block or on the objects without
    normals gives the same values. ``owner`` names the caller in errors.
    """
    from ..preprocessing._normals import estimate_normals_batch

    points, offsets, has = clouds.points, clouds.offsets, clouds.has_normals
    if clouds.normals is not None and has.all():
        return points, clouds.normals, offsets
    if clouds.normals is None:
        normals = estimate_normals_batch(points, offsets, n_neighbors, orientation, n_threads, owner=owner)
        return points, normals, offsets
    missing = np.flatnonzero(~has)
    sub = np.concatenate([points[offsets[k]:offsets[k + 1]] for k in missing])
    sub_off = np.zeros(len(missing) + 1, dtype=np.int64)
    np.cumsum(offsets[missing + 1] - offsets[missing], out=sub_off[1:])
    est = estimate_normals_batch(sub, sub_off, n_neighbors, orientation, n_threads, owner=owner)
    normals = clouds.normals.copy()
    for j, k in enumerate(missing):
        normals[offsets[k]:offsets[k + 1]] = est[sub_off[j]:sub_off[j + 1]]
    return points, normals, offsets


def _describe_chunk(est, clouds, *args, params):
    """One joblib task: the rows of a chunk of packed clouds (``args`` = per-object arrays, then the chunk's
    first index; ``params`` = the estimator's resolved parameters, checked once by ``transform``)."""
    *per_object, first_index = args
    return est._describe(clouds, params, *per_object, first_index=first_index)
