"""The ahead-of-time kernels as a setuptools extension (the rest of the metadata is pyproject.toml's).

``pip install`` (also ``-e``) compiles rtreflect/kernels/_aot with numba.pycc (`rtreflect.kernels.build`),
so a render imports no numba; where no C compiler is found the extension is skipped and the kernels are
compiled by numba's JIT on first use instead (rtreflect.kernels.compiled).
"""

import sys
from pathlib import Path

from setuptools import setup

sys.path.insert(0, str(Path(__file__).resolve().parent))  # the build imports the kernels from this source tree

from rtreflect.kernels.build import extensions  # noqa: E402

setup(ext_modules=extensions())
