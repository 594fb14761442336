"""The product suite's fixtures (planar arms, SARCOS, the tiny Jaco collections) for the studies' tests."""

from tests.conftest import arm3, arm3_rbd, arm3_test, arm3_train, sarcos_dir  # noqa: F401
from tests.test_collect_options import arms  # noqa: F401
