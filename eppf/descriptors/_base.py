"""The base class of every point-cloud descriptor transformer.

A descriptor maps a list of point clouds (arrays of shape (n_i, 3), or (n_i, 6)
with normals in columns 3-5) to one row per object. What every descriptor does
the same way is written here once:

- ``fit`` checks the parameters and the clouds, lets the subclass learn from
  them (:meth:`PointCloudDescriptor._learn`, e.g. EPPF's data-set scale) and
  records ``n_features_out_``;
- ``transform`` validates the clouds once (all of them, in one compiled pass),
  draws the per-object inputs (seeds from ``random_state``, scales) for the
  whole input before chunking, and hands chunks of objects to joblib
  (:func:`eppf.utils.transform_in_chunks`), so results never depend on threads,
  chunk sizes or where a chunk runs;
- kernel status codes become a ``ValueError`` naming the estimator and the
  object (:meth:`PointCloudDescriptor._raise_for_status`);
- tags for ragged (non-tabular) input and ``get_feature_names_out``.

A subclass provides ``_check_params`` (validated, resolved parameters),
``_n_features``, ``_describe`` (the rows of one chunk) and
``_feature_names``, and sets ``_min_points``.
"""

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils.validation import check_is_fitted

from ..utils import check_n_jobs, check_point_clouds, object_seeds, pack_point_clouds, transform_in_chunks

__all__ = ["PointCloudDescriptor"]


class PointCloudDescriptor(TransformerMixin, BaseEstimator):
    """Base class of eppf's point-cloud descriptor transformers.

    Not for direct use: subclasses implement the hooks described in the
    module docstring. ``random_state``, ``n_jobs`` and ``verbose`` are read
    when a subclass has them.
    """

    #: Fewest points a cloud may have.
    _min_points = 2
    #: Label of the progress bar (``verbose``).
    _progress_label = ""

    # ----------------------------------------------------------------- hooks
    def _check_params(self):  # pragma: no cover - every subclass overrides it
        """Validate the parameters; return them resolved (any object the other hooks take)."""
        raise NotImplementedError

    def _n_features(self, params):  # pragma: no cover - every subclass overrides it
        """Width of the output for resolved ``params``."""
        raise NotImplementedError

    def _learn(self, clouds, params):
        """Learn from the validated training clouds (nothing by default)."""

    def _per_object(self, clouds, params):
        """Per-object inputs drawn for the whole input before chunking: one seed per object."""
        return (object_seeds(getattr(self, "random_state", None), len(clouds)),)

    def _describe(self, clouds, params, *per_object, first_index):  # pragma: no cover - overridden
        """The rows of one chunk of validated clouds."""
        raise NotImplementedError

    def _feature_names(self):  # pragma: no cover - every subclass overrides it
        """One name per output column."""
        raise NotImplementedError

    # ------------------------------------------------------------- plumbing
    def _threads(self):
        return check_n_jobs(getattr(self, "n_jobs", None), owner=type(self).__name__)

    def _validate_clouds(self, X, n_threads=1):
        return check_point_clouds(X, owner=type(self).__name__, min_points=self._min_points, n_threads=n_threads)

    def _points_and_normals(self, clouds, n_neighbors, orientation, n_threads):
        """Pack validated clouds into ``points``, ``normals`` (N, 3) and ``offsets``.

        Clouds given with normals keep them; the others get PCA normals from
        ``n_neighbors`` neighbours (:func:`eppf.preprocessing.estimate_normals`),
        oriented by ``orientation``.
        """
        from ..preprocessing._normals import estimate_normals_batch

        points, _, offsets = pack_point_clouds([c[:, :3] for c in clouds])
        normals = np.empty_like(points)
        missing = [k for k, c in enumerate(clouds) if c.shape[1] == 3]
        for k, c in enumerate(clouds):
            if c.shape[1] == 6:
                normals[offsets[k] : offsets[k + 1]] = c[:, 3:]
        if missing:
            sub_pts, _, sub_off = pack_point_clouds([clouds[k][:, :3] for k in missing])
            est = estimate_normals_batch(sub_pts, sub_off, n_neighbors, orientation, n_threads,
                                         owner=type(self).__name__)
            for j, k in enumerate(missing):
                normals[offsets[k] : offsets[k + 1]] = est[sub_off[j] : sub_off[j + 1]]
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
        clouds = self._validate_clouds(X)
        self._learn(clouds, params)
        self.n_features_out_ = int(self._n_features(params))
        return self

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
        clouds = self._validate_clouds(X, self._threads())
        per_object = self._per_object(clouds, params)
        return transform_in_chunks(
            _describe_chunk, self, clouds, per_object, n_features=self.n_features_out_,
            verbose=getattr(self, "verbose", 0), desc=self._progress_label,
        )

    def get_feature_names_out(self, input_features=None):
        """Names of the output columns.

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


def _describe_chunk(est, clouds, *args):
    """One joblib task: the rows of a chunk (``args`` = per-object arrays, then the chunk's first index)."""
    *per_object, first_index = args
    return est._describe(clouds, est._check_params(), *per_object, first_index=first_index)
