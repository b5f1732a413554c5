"""Golden-image helpers for users' pytest suites (the stable import path).

The implementation lives in :mod:`rtreflect.ci.golden`; this module keeps
``from rtreflect.testing import assert_images_match, render_golden`` working.
"""

from .ci.golden import *  # noqa: F401,F403
from .ci.golden import __all__  # noqa: F401
