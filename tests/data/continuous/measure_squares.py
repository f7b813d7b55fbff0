"""How often NumPy's `x ** 2` differs from the correctly rounded square, in float64 and float32.

Gymnasium's Pendulum-v1 squares its three cost terms with `** 2`; NumPy (and Python) compute that with the C
library's `pow` and `powf`. Where those are not correctly rounded, arld's reward (correctly rounded squares, the
same bytes on every machine) differs from Gymnasium's by the misrounded ulp; tests/continuous_conformance.rs
accepts exactly those rewards. Run with the Python that has NumPy:

    python tests/data/continuous/measure_squares.py

Measured with NumPy 2.4.6 on glibc 2.36 (x86-64): 166 of 200,000 float64 squares and 160 of 200,000 float32
squares were one ulp off.
"""

import platform

import numpy as np

N = 200_000
rng = np.random.default_rng(0)
halves = rng.uniform(-2.0, 2.0, N).astype(np.float32)
off32 = sum(1 for u in halves if u**2 != np.float32(np.float64(u) * np.float64(u)))
doubles = rng.uniform(-np.pi, np.pi, N)
off64 = sum(1 for x in doubles if np.float64(x) ** 2 != x * x)
print(f"NumPy {np.__version__}, {platform.libc_ver()}: {off64} of {N} float64 squares and {off32} of {N} "
      f"float32 squares are not correctly rounded")
