"""The compiled kernels of the solver (fabplan/solve/normal_sums.c); the rest of the build is
declared in pyproject.toml. The extension is optional: without a C compiler fabplan
installs and runs on its numpy path (fabplan.solve.kernels)."""

import sys

from setuptools import Extension, setup

# no fused multiply-add: the kernels must round as numpy does (see normal_sums.c)
flags = [] if sys.platform == "win32" else ["-O3", "-ffp-contract=off"]

setup(ext_modules=[Extension("fabplan.solve.normal_sums", ["fabplan/solve/normal_sums.c"],
                             extra_compile_args=flags, optional=True)])
