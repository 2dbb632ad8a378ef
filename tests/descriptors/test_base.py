"""The descriptors' common skeleton: one base class, one parameter-validation mechanism."""

import re

import numpy as np
import pytest

import eppf.descriptors as descriptors
from eppf.descriptors._base import PointCloudDescriptor
from eppf.registry import DESCRIPTORS
from eppf.utils._param_validation import IntTuple, InvalidParameterError, make_constraint

# Compositions of descriptors (DescriptorUnion and its presets) are meta-estimators over these,
# checked in test_union.py; every descriptor proper is one of the classes below.
CLASSES = sorted({DESCRIPTORS[name].estimator_class() for name in DESCRIPTORS} | {descriptors.GASDColorTransformer},
                 key=lambda c: c.__name__)
CLASSES = [c for c in CLASSES if not issubclass(c, descriptors.DescriptorUnion)]


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_every_descriptor_is_a_point_cloud_descriptor_with_constraints_for_every_parameter(cls):
    assert issubclass(cls, PointCloudDescriptor)
    # The skeleton is the base's: no subclass re-implements it.
    for name in ("fit", "transform", "get_feature_names_out", "__sklearn_tags__"):
        owner = next(k for k in cls.__mro__ if name in vars(k))
        assert owner in (PointCloudDescriptor, cls) and (owner is PointCloudDescriptor or name in ("fit", "transform")), name
    params = cls().get_params(deep=False)
    assert set(cls._parameter_constraints) == set(params)
    for name, value in params.items():  # every default is accepted
        assert any(make_constraint(c).is_satisfied_by(value) for c in cls._parameter_constraints[name]), name


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_every_parameter_is_validated_with_a_message_naming_estimator_and_parameter(cls):
    rng = np.random.default_rng(0)
    cloud = rng.normal(size=(40, 6 if cls is descriptors.GASDColorTransformer else 3))
    if cls is descriptors.GASDColorTransformer:
        cloud[:, 3:] = rng.integers(0, 256, size=(40, 3))
    for name in cls().get_params(deep=False):
        bad = object()
        with pytest.raises(InvalidParameterError, match=re.escape(f"{cls.__name__}: {name} must be ")) as info:
            cls(**{name: bad}).fit([cloud])
        assert str(info.value).endswith(f"got {bad!r}")
        # Raised again in transform, when set after fit.
        est = cls().fit([cloud])
        est.set_params(**{name: bad})
        with pytest.raises(InvalidParameterError, match=re.escape(f"{cls.__name__}: {name} must be ")):
            est.transform([cloud])


def test_int_tuple_constraint():
    c = IntTuple(4, 1, 64)
    assert c.is_satisfied_by((20, 4, 5, 3)) and c.is_satisfied_by([1, 1, 1, 64])
    assert c.is_satisfied_by(np.array([2, 3, 4, 5]))
    for bad in [(20, 4, 5), (20, 4, 5, 3, 1), (0, 4, 5, 3), (65, 4, 5, 3), (2.0, 4, 5, 3), (True, 4, 5, 3), "2345",
                20, None, {1: 2}]:
        assert not c.is_satisfied_by(bad), bad
    capped = IntTuple(2, 1, 1024, max_product=100)
    assert capped.is_satisfied_by((10, 10)) and not capped.is_satisfied_by((10, 11))
    assert str(capped) == "a tuple of 2 ints in [1, 1024] with a product of at most 100"
    with pytest.raises(ValueError):
        IntTuple(0, 1, 2)
    with pytest.raises(TypeError):
        IntTuple(2, 1.0, 2)


def test_extra_columns_reach_describe_with_their_cloud():
    # GASD colour's RGB columns travel as a per-object input: a cloud's row
    # depends on its own colours only, wherever it stands in the input.
    rng = np.random.default_rng(1)
    xyz = [rng.normal(size=(50, 3)) * [3, 2, 1] for _ in range(3)]
    rgb = [rng.integers(0, 256, size=(50, 3)) for _ in range(3)]
    X = [np.hstack([p, c]) for p, c in zip(xyz, rgb)]
    est = descriptors.GASDColorTransformer().fit(X)
    rows = est.transform(X)
    assert np.array_equal(est.transform(X[::-1]), rows[::-1])
    recoloured = [X[0], np.hstack([xyz[1], 255 - rgb[1]]), X[2]]
    other = est.transform(recoloured)
    shape = (2 * est.shape_half_grid_size) ** 3 * est.shape_hists_size
    assert np.array_equal(other[[0, 2]], rows[[0, 2]])
    assert np.array_equal(other[1, :shape], rows[1, :shape]) and not np.array_equal(other[1], rows[1])


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
@pytest.mark.parametrize("factor", [2.0 ** 300, 2.0 ** -300])
def test_extreme_power_of_two_scale_gives_the_sane_scale_output(cls, factor):
    # clouds outside the kernels' magnitude window are rescaled by an exact power of two: a
    # descriptor invariant to scale gives at 2**+-300 the bits it gives at scale 1
    from eppf.datasets import make_shapes

    if cls is descriptors.VFHTransformer:
        pytest.skip("VFH is not scale-invariant: PCL's homogeneous viewpoint adds a unit length (pcl_homogeneous)")
    clouds = make_shapes(1, n_points=128, classes=["box", "sphere"], return_X_y=True, random_state=0)[0]
    if cls is descriptors.GASDColorTransformer:
        rng = np.random.default_rng(0)
        clouds = [np.hstack([c, rng.uniform(0, 255, size=(len(c), 3))]) for c in clouds]
    params = {"n_jobs": 1}
    if "random_state" in cls().get_params():
        params["random_state"] = 0
    if "scaling" in cls().get_params():
        params["scaling"] = "object"
    scaled = [np.hstack([c[:, :3] * factor, c[:, 3:]]) for c in clouds]
    est = cls(**params)
    np.testing.assert_array_equal(est.fit_transform(scaled), est.fit_transform(clouds))
