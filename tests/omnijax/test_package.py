"""The package's lazy public names (omnijax._lazy) and the exact medians by counts of the noise gate."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from omnijax.detection._change import _stepped_median
from tests.paths import ROOT


def test_names_and_subpackages_are_there_when_read_and_the_emulator_needs_no_jax():
    code = ("import sys, omnijax, omnijax.config as c\n"
            "assert 'jax' not in sys.modules\n"
            "from runtime.ptz.profile import default_profile\n"
            "default_profile('visca')\n"
            "assert 'jax' not in sys.modules, 'the PTZ profile imported JAX'\n"
            "assert omnijax.detect.__name__ == 'detect' and c.Rig.__name__ == 'Rig'\n"
            "assert omnijax.world.build_world.__name__ == 'build_world'\n"
            "assert 'learn_background' in dir(omnijax) and 'Rig' in omnijax.__all__\n"
            "try:\n    omnijax.no_such_name\nexcept AttributeError as e:\n    print(e)\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "module 'omnijax' has no attribute 'no_such_name'"


@pytest.mark.parametrize("step,top", [(1.0, 255), (1.0 / 25, 255 * 25)])
def test_the_median_by_counts_is_nanmedian(step, top):
    rng = np.random.default_rng(45)  # 100 arrays of 1-499 samples, 30 % NaN, NaN-padded to one shape (one compile)
    for _ in range(100):
        n = int(rng.integers(1, 500))
        v = np.full(500, np.nan, np.float32)
        v[:n] = rng.integers(0, top + 1, n) * step
        v[rng.random(500) < 0.3] = np.nan
        got = float(_stepped_median(v, step, top))
        if np.isnan(v).all():
            assert np.isnan(got)
        else:
            assert got == pytest.approx(float(np.nanmedian(v)), rel=1e-5, abs=1e-6)
