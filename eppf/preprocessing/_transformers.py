"""The perturbation and sampling transformers of :mod:`eppf.preprocessing`."""

import numbers

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin

from . import _perturb
from ._perturb import CONSTRAINTS
from ..utils._param_validation import RANDOM_STATE, Interval, validate_params
from ..utils._sampling import object_rng, sample_mesh
from ..utils._validation import check_point_clouds, object_seeds

__all__ = ["GaussianNoise", "Occlusion", "RandomDropout", "RandomRotation", "RandomScaling", "Resampler", "sample_mesh"]


class _CloudTransformer(TransformerMixin, BaseEstimator):
    """Shared plumbing: validation, per-object seeding, tags.

    Parameters are checked against ``_parameter_constraints`` (the
    perturbations' :data:`eppf.preprocessing._perturb.CONSTRAINTS`).
    """

    _parameter_constraints = {}

    def _check_params(self):
        validate_params(self)

    def _apply(self, cloud, rng):  # pragma: no cover - overridden
        raise NotImplementedError

    def fit(self, X, y=None):
        """Check the parameters and the clouds; nothing is learned.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds, normals in the last three columns.
        y : None
            Ignored.

        Returns
        -------
        self : object
            The transformer.
        """
        self._check_params()
        check_point_clouds(X, owner=type(self).__name__)
        return self

    def transform(self, X):
        """Perturb every cloud.

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds, normals in the last three columns.

        Returns
        -------
        X_new : list of ndarray
            New float64 clouds; the input is not modified. Normals follow
            their points.
        """
        self._check_params()
        clouds = check_point_clouds(X, owner=type(self).__name__)
        seeds = object_seeds(self.random_state, len(clouds))
        out = []
        for k, (cloud, seed) in enumerate(zip(clouds, seeds)):
            try:
                out.append(self._apply(cloud, object_rng(seed)))
            except _perturb.NotFiniteError as exc:  # named after this transformer and the cloud
                raise _perturb.NotFiniteError(type(self).__name__, exc.what, exc.remedy, index=k) from None
        return out

    def fit_transform(self, X, y=None):
        """Perturb every cloud (``fit`` learns nothing, so this is :meth:`transform`, validating once).

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds, normals in the last three columns.
        y : None
            Ignored.

        Returns
        -------
        X_new : list of ndarray
            As :meth:`transform`.
        """
        return self.transform(X)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.requires_fit = False
        tags.input_tags.two_d_array = False
        tags.input_tags.three_d_array = True
        return tags


class GaussianNoise(_CloudTransformer):
    """Add Gaussian noise to the coordinates of point clouds.

    The perturbation of the paper's noise experiment (Fig. 8): each
    coordinate receives independent noise of standard deviation
    ``sigma`` in units of the cube the object fits in. Normals are kept as
    they are (re-estimate them from the noisy points to model a real sensor).

    Parameters
    ----------
    sigma : float, default=0.01
        Standard deviation of the noise, >= 0.
    relative_to : {"unit_cube", "none"}, default="unit_cube"
        ``"unit_cube"``: ``sigma`` is a fraction of the largest side of each
        cloud's bounding box. ``"none"``: ``sigma`` is in the cloud's units.
    random_state : int, RandomState instance or None, default=None
        Seed of the noise; see the module notes on per-object seeds.

    See Also
    --------
    RandomDropout : Remove random points.
    Occlusion : Remove the side of an object facing away from a sensor.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.preprocessing import GaussianNoise
    >>> clouds = [np.random.RandomState(0).uniform(size=(50, 3))]
    >>> noisy = GaussianNoise(0.05, random_state=0).fit_transform(clouds)
    >>> noisy[0].shape
    (50, 3)
    """

    def __init__(self, sigma=0.01, *, relative_to="unit_cube", random_state=None):
        self.sigma = sigma
        self.relative_to = relative_to
        self.random_state = random_state

    _parameter_constraints = {
        "sigma": CONSTRAINTS["sigma"], "relative_to": CONSTRAINTS["relative_to"], "random_state": RANDOM_STATE,
    }

    def _apply(self, cloud, rng):
        return _perturb.add_gaussian_noise(cloud, self.sigma, relative_to=self.relative_to, random_state=rng)


class RandomDropout(_CloudTransformer):
    """Remove a random share of the points of each cloud.

    Parameters
    ----------
    fraction : float, default=0.1
        Share of the points to remove, ``0 <= fraction < 1``; at least two
        points are always kept.
    random_state : int, RandomState instance or None, default=None
        Seed of the choice of points.

    See Also
    --------
    Occlusion : View-dependent removal of points.
    Resampler : Draw a fixed number of points.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.preprocessing import RandomDropout
    >>> clouds = [np.random.RandomState(0).uniform(size=(100, 3))]
    >>> RandomDropout(0.25, random_state=0).fit_transform(clouds)[0].shape
    (75, 3)
    """

    def __init__(self, fraction=0.1, *, random_state=None):
        self.fraction = fraction
        self.random_state = random_state

    _parameter_constraints = {"fraction": CONSTRAINTS["fraction"], "random_state": RANDOM_STATE}

    def _apply(self, cloud, rng):
        return _perturb.random_dropout(cloud, self.fraction, random_state=rng)


class Occlusion(_CloudTransformer):
    """Remove the side of each cloud that faces away from a sensor.

    The points are ranked by their projection on the viewing direction and
    the ``fraction`` farthest from the sensor are removed (a plane cut).

    Parameters
    ----------
    fraction : float, default=0.3
        Share of the points to remove, ``0 <= fraction < 1``.
    direction : {"x", "y", "z"} or array-like of shape (3,), default=None
        Direction from the object to the sensor, the same for every cloud.
        ``None`` draws one direction per cloud uniformly on the sphere.
    random_state : int, RandomState instance or None, default=None
        Seed of the random directions.

    See Also
    --------
    RandomDropout : Removal independent of geometry.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.preprocessing import Occlusion
    >>> clouds = [np.random.RandomState(0).normal(size=(100, 3))]
    >>> Occlusion(0.3, direction="z").fit_transform(clouds)[0].shape
    (70, 3)
    """

    def __init__(self, fraction=0.3, *, direction=None, random_state=None):
        self.fraction = fraction
        self.direction = direction
        self.random_state = random_state

    _parameter_constraints = {
        "fraction": CONSTRAINTS["fraction"], "direction": [*CONSTRAINTS["direction"], None], "random_state": RANDOM_STATE,
    }

    def _apply(self, cloud, rng):
        return _perturb.occlude(cloud, self.fraction, direction=self.direction, random_state=rng)


class RandomRotation(_CloudTransformer):
    """Rotate each cloud (and its normals) by its own random rotation.

    Parameters
    ----------
    axis : {"x", "y", "z"} or array-like of shape (3,), default=None
        ``None`` draws rotations uniformly from SO(3); otherwise rotations are
        about this axis by a uniform angle.
    center : {"centroid", "origin"}, default="centroid"
        Fixed point of the rotation.
    random_state : int, RandomState instance or None, default=None
        Seed of the rotations.

    See Also
    --------
    RandomScaling : Random stretches along the axes.
    GaussianNoise : Noise on the coordinates.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.preprocessing import RandomRotation
    >>> clouds = [np.random.RandomState(0).normal(size=(10, 3))]
    >>> RandomRotation(axis="z", random_state=0).fit_transform(clouds)[0].shape
    (10, 3)
    """

    def __init__(self, *, axis=None, center="centroid", random_state=None):
        self.axis = axis
        self.center = center
        self.random_state = random_state

    _parameter_constraints = {
        "axis": [*CONSTRAINTS["axis"], None], "center": CONSTRAINTS["center"], "random_state": RANDOM_STATE,
    }

    def _apply(self, cloud, rng):
        return _perturb.random_rotation(cloud, axis=self.axis, center=self.center, random_state=rng)


class RandomScaling(_CloudTransformer):
    """Stretch each cloud by random factors along the coordinate axes.

    Augmentation for the descriptor pools of :class:`eppf.classifiers.EPPF4DClassifier`:
    an anisotropic stretch changes an object's proportions a little, which
    the scale-invariant descriptor (``scaling="object"``) does see, so
    descriptors of stretched copies teach a classifier that a slightly wider
    chair is still a chair (on ModelNet10 they lifted the 4D network's test
    accuracy above that of pools of plain draws: see the documentation's
    Performance page, "CNN training"). Normals follow the surface: each is
    multiplied by the inverse factors and scaled back to unit length,
    so it stays perpendicular to the stretched surface.

    Parameters
    ----------
    low, high : float, default=0.8, 1.25
        Range of the factors, ``0 < low <= high``, drawn log-uniformly per
        object (and per axis when ``anisotropic``).
    anisotropic : bool, default=True
        One factor per axis, or one shared by all three axes.
    center : {"centroid", "origin"}, default="centroid"
        Fixed point of the scaling.
    random_state : int, RandomState instance or None, default=None
        Seed of the factors.

    See Also
    --------
    RandomRotation : Random rotations.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.preprocessing import RandomScaling
    >>> clouds = [np.random.RandomState(0).uniform(size=(20, 3))]
    >>> RandomScaling(random_state=0).fit_transform(clouds)[0].shape
    (20, 3)
    """

    def __init__(self, low=0.8, high=1.25, *, anisotropic=True, center="centroid", random_state=None):
        self.low = low
        self.high = high
        self.anisotropic = anisotropic
        self.center = center
        self.random_state = random_state

    _parameter_constraints = {
        "low": CONSTRAINTS["low"], "high": CONSTRAINTS["high"], "anisotropic": CONSTRAINTS["anisotropic"],
        "center": CONSTRAINTS["center"], "random_state": RANDOM_STATE,
    }

    def _check_params(self):
        super()._check_params()
        _perturb._check_scale_range(self.low, self.high, type(self).__name__)

    def _apply(self, cloud, rng):
        return _perturb.random_scaling(
            cloud, self.low, self.high, anisotropic=self.anisotropic, center=self.center, random_state=rng
        )

    def transform(self, X):
        """Stretch every cloud.

        Each cloud's factors come from its own seed, as
        :func:`~eppf.preprocessing._perturb.random_scaling` draws them; the
        stretching itself runs over all clouds at once (the same values as
        cloud by cloud, faster for many small clouds).

        Parameters
        ----------
        X : list of array-like of shape (n_i, 3) or (n_i, 6)
            Point clouds, normals in the last three columns.

        Returns
        -------
        X_new : list of ndarray
            New float64 clouds; the input is not modified. Normals follow
            their points.
        """
        self._check_params()
        clouds = check_point_clouds(X, owner=type(self).__name__)
        low, high, anisotropic = float(self.low), float(self.high), bool(self.anisotropic)
        factors = np.empty((len(clouds), 3))
        for k, seed in enumerate(object_seeds(self.random_state, len(clouds))):
            factors[k] = _perturb._scaling_factors(object_rng(seed), low, high, anisotropic)
        out = _perturb._scale_clouds(clouds, factors, self.center)
        for k, cloud in enumerate(out):
            if not np.isfinite(cloud).all():
                raise _perturb.NotFiniteError(type(self).__name__, "stretched", _perturb.SCALING_REMEDY, index=k)
        return out


class Resampler(_CloudTransformer):
    """Draw a fixed number of points from each cloud.

    Clouds with at least ``n_points`` points are subsampled without
    replacement; smaller ones keep every point and repeat random ones.

    Parameters
    ----------
    n_points : int, default=2048
        Points per output cloud, >= 2 (the paper feeds PointNet 2,048).
    random_state : int, RandomState instance or None, default=None
        Seed of the draw.

    See Also
    --------
    RandomDropout : Remove a share of the points.
    sample_mesh : Sample points from the surface of a mesh.

    Examples
    --------
    >>> import numpy as np
    >>> from eppf.preprocessing import Resampler
    >>> clouds = [np.zeros((5, 3)) + np.arange(5)[:, None], np.ones((300, 3)) * np.arange(300)[:, None]]
    >>> [c.shape for c in Resampler(64, random_state=0).fit_transform(clouds)]
    [(64, 3), (64, 3)]
    """

    def __init__(self, n_points=2048, *, random_state=None):
        self.n_points = n_points
        self.random_state = random_state

    _parameter_constraints = {
        "n_points": [Interval(numbers.Integral, 2, None, closed="left")], "random_state": RANDOM_STATE,
    }

    def _apply(self, cloud, rng):
        return _perturb.resample(cloud, int(self.n_points), random_state=rng)
