"""Golden-image helpers for users' pytest suites (the stable import path), and rtreflect's pytest plugin.

The implementation lives in :mod:`rtreflect.ci.golden`; this module keeps
``from rtreflect.testing import assert_images_match, render_golden`` working. It is also
the pytest plugin registered by the ``pytest11`` entry point (`rtreflect.ci.pytest_plugin`):
the ``rtreflect_golden`` fixture and the ``--rtreflect-update-goldens`` option.
"""

from .ci.golden import *  # noqa: F401,F403
from .ci.golden import __all__  # noqa: F401

try:  # the plugin's hooks and fixture, for pytest to find here; without pytest the helpers above still import
    from .ci.pytest_plugin import (pytest_addoption, pytest_configure, pytest_terminal_summary,  # noqa: F401
                                   rtreflect_golden)
except ImportError:  # pragma: no cover - pytest not installed
    pass
