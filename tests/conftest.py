import os

import pytest
import warp as wp

wp.config.log_level = wp.LOG_ERROR
wp.init()


@pytest.fixture(scope="session")
def device():
    return os.environ.get("MPM_TEST_DEVICE", "cpu")
