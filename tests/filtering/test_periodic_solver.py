"""The linear solver of the cross-stride smoothers: banded, dense and sparse paths agree."""

import numpy as np
import pytest
from scipy import sparse

from probreg.filtering import periodic
from probreg.filtering.periodic import _SPDSolver


def _banded_spd(n, far, rng):
    A = np.eye(n) * 4.0
    for k, v in ((1, -1.5), (2, 0.4), (far, -0.6), (far + 1, -0.3)):
        A += np.diag(np.full(n - k, v), k) + np.diag(np.full(n - k, v), -k)
    return A + np.diag(rng.uniform(1.0, 2.0, n))


@pytest.mark.parametrize("far", [3, 37, 150])
def test_banded_dense_and_sparse_solutions_agree(far):
    rng = np.random.default_rng(far)
    A = _banded_spd(250, far, rng)
    b = rng.normal(size=(250, 2))
    ref = np.linalg.solve(A, b)
    s = _SPDSolver(A)
    # a band narrower than a third of the system is factorised banded, a wider one densely
    assert (s._band is not None) == (far + 1 < 250 // 3)
    assert np.allclose(s.solve(b), ref, atol=1e-12)
    assert np.allclose(_SPDSolver(sparse.csr_matrix(A)).solve(b), ref, atol=1e-12)
    assert np.allclose(_SPDSolver(A, band=far + 1).solve(b), ref, atol=1e-12)


def test_large_systems_use_sparse_lu(monkeypatch):
    rng = np.random.default_rng(1)
    A = _banded_spd(80, 5, rng)
    monkeypatch.setattr(periodic, "DENSE_MAX", 10)
    s = _SPDSolver(sparse.csc_matrix(A))
    assert s._lu is not None and s._band is None and s._cho is None
    b = rng.normal(size=80)
    assert np.allclose(s.solve(b), np.linalg.solve(A, b), atol=1e-12)
