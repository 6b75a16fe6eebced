"""One tolerance table for the whole suite: relative tolerances by dtype and by kind of comparison."""

import numpy as np

#: Exact identities (two ways of writing one formula), relative.
EXACT = {np.float64: 1e-12, np.float32: 1e-5}
#: Autodiff against a hand-derived closed form, relative (float64).
CLOSED_FORM = 1e-9
#: Autodiff against central finite differences (step ~ 1e-6 relative), relative.
FINITE_DIFF = 1e-5
#: The same through the calibrated zoom's root (found to 1e-12 in its normal score, so central
#: differences of what depends on it carry ~1e-7 relative noise), relative.
ROOT_FINITE_DIFF = 1e-4
#: Monte Carlo comparisons are statistical: each test states its own n and bound.
