"""optkin's Sobol' points and Poisson limits equal SciPy's (``scipy.stats`` is imported here,
in the test, and nowhere on optkin's solving path)."""

import subprocess
import sys
import warnings

import numpy as np
import pytest
from scipy.stats import chi2, qmc

from optkin.solvers.enumerate import poisson_upper
from optkin.solvers.sobol import sobol_points


@pytest.mark.parametrize("dim", [1, 2, 3, 4, 5, 7, 12, 21, 40])
def test_sobol_points_equal_scipy(dim):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for n in (1, 5, 1024, 3000):
            assert np.array_equal(sobol_points(dim, n), qmc.Sobol(dim, scramble=False).random(n))
        for start, n in ((1, 7), (1000, 100), (4095, 3), (65536, 512)):
            engine = qmc.Sobol(dim, scramble=False)
            engine.fast_forward(start)
            assert np.array_equal(sobol_points(dim, n, start=start), engine.random(n)), start


def test_sobol_points_rejects_bad_sizes():
    with pytest.raises(ValueError, match="dim >= 1"):
        sobol_points(0, 4)
    with pytest.raises(ValueError, match="at most"):
        sobol_points(2, 4, start=(1 << 30) - 1)


def test_poisson_upper_is_the_chi2_quantile():
    for k in (0, 1, 2, 7, 50, 128, 129, 500):
        assert poisson_upper(k) == pytest.approx(chi2.ppf(0.99, 2 * k + 2) / 2, rel=1e-12)
    assert poisson_upper(0) == pytest.approx(-np.log(0.01), rel=1e-12)


def test_solvers_do_not_import_scipy_stats():
    code = ("import sys, optkin, optkin.solvers.enumerate, optkin.solvers.inverse, "
            "optkin.problems.runner; print('scipy.stats' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "False"
