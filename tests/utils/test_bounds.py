import numpy as np

from eppf.utils._bounds import largest_sides


def test_largest_sides_are_those_of_np_ptp():
    rng = np.random.default_rng(3)
    clouds = [rng.normal(size=(n, k)) * s for n, k, s in ((5, 3, 1.0), (1, 6, 2.0), (40, 3, 1e-300), (7, 6, 1e5))]
    clouds.append(np.array([[1e308, 0, 0], [-1e308, 1, 1]]))
    with np.errstate(over="ignore"):
        expected = [np.ptp(c[:, :3], axis=0).max() for c in clouds]
    got = largest_sides(clouds)
    assert got.tolist() == expected and np.isinf(got[-1])
