"""The compiled kernels: the solver's sums (fabplan/solve/normal_sums.c) and the fit of
mold placements (fabplan/fabricate/molds/mold_fit_kernel.c); the rest of the build is
declared in pyproject.toml. The extensions are optional: without a C compiler fabplan
installs and runs on its numpy paths (fabplan.solve.kernels, fabplan.fabricate.molds.mold_fits)."""

import sys

from setuptools import Extension, setup

# no fused multiply-add: the kernels must round as numpy does (see normal_sums.c)
flags = [] if sys.platform == "win32" else ["-O3", "-ffp-contract=off"]

setup(ext_modules=[
    Extension("fabplan.solve.normal_sums", ["fabplan/solve/normal_sums.c"],
              extra_compile_args=flags, optional=True),
    # the fit of mold placements (fabplan.fabricate.molds.mold_fits)
    Extension("fabplan.fabricate.molds.mold_fit_kernel", ["fabplan/fabricate/molds/mold_fit_kernel.c"],
              extra_compile_args=flags, optional=True),
])
