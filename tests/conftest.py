import os

import pytest
import warp as wp

wp.config.log_level = wp.LOG_ERROR
wp.init()

DEVICES = ("cpu", "cuda")


def pytest_addoption(parser):
    parser.addoption("--device", default=None, choices=DEVICES,
                     help="the Warp device the tests run on (default: $MPM_TEST_DEVICE, else cpu)")


def pytest_configure(config):
    """The test device reaches every run: in-process through the tests'
    helpers, in the command-line runs through MPM_DEVICE (run.device's default)."""
    device = config.getoption("--device") or os.environ.get("MPM_TEST_DEVICE", "cpu")
    if device not in DEVICES:
        raise pytest.UsageError(f"MPM_TEST_DEVICE={device!r}; accepted: {', '.join(DEVICES)}")
    if device == "cuda" and not wp.is_cuda_available():
        raise pytest.UsageError("--device cuda: Warp finds no CUDA device on this machine")
    os.environ["MPM_TEST_DEVICE"] = os.environ["MPM_DEVICE"] = device
    config.addinivalue_line("markers", "bitwise: asserts that two runs agree bit for bit; on CUDA the "
                            "order of atomic adds varies between runs, so these run on the CPU only")


def pytest_collection_modifyitems(config, items):
    if os.environ["MPM_TEST_DEVICE"] != "cuda":
        return
    skip = pytest.mark.skip(reason="bit-for-bit equality of two runs: atomic sums on CUDA depend on thread order")
    for item in items:
        if "bitwise" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def device():
    return os.environ["MPM_TEST_DEVICE"]
