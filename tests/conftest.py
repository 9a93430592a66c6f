"""The `driver` fixture: a test that takes it runs once on every OpenCL
device of the machine (each driver fractalc registers, and any the system
has), as `fractalc.loads(..., device=driver)`; a device whose driver cannot
build fractalc's kernels here is skipped with the driver's own reason. The
rest of the suite runs on the default device.

The `opencl` marker: a test that builds or runs a kernel carries it; every
other test (parse, check, lower, emit, the command line's mistakes) runs
with OpenCL out of reach, so `pytest -m "not opencl"` tests the stages
before `build` in seconds, on a machine without a driver too, and a test
that reaches for a device without the marker fails at once."""
from __future__ import annotations

import re

import pytest


def _devices():
    from fractalc.devices import list_devices
    return list_devices()


def _name(info) -> str:
    """"intel-cpu", "pocl-cpu", "nvidia-gpu": the driver's first word and the kind."""
    words = re.findall(r"[a-z]+", info.driver_label.replace("(R)", "").lower())
    return "-".join(words[:1] + [info.kind.lower()])


def pytest_generate_tests(metafunc):
    if "driver" in metafunc.fixturenames:
        infos = _devices()
        names = [_name(info) for info in infos]
        ids = [name if names.count(name) == 1 else f"{name}-{info.index}" for name, info in zip(names, infos)]
        metafunc.parametrize("driver", [str(info.index) for info in infos], ids=ids, indirect=True)


@pytest.fixture
def driver(request):
    from fractalc.devices import lane_choice, list_devices
    from fractalc.errors import RenderError
    info = list_devices()[int(request.param)]
    try:
        lane_choice(info)
    except RenderError as error:
        pytest.skip(str(error))
    return request.param


def pytest_configure(config):
    """FRACTALC_RECORD_SCENES=FILE: append every scene the tests load to
    FILE (JSON lines of text and path), the corpus of
    benchmarks/kernel_snapshot.py."""
    import os
    record = os.environ.get("FRACTALC_RECORD_SCENES")
    if not record:
        return
    import functools
    import json
    import fractalc
    from fractalc import api
    original = api.loads

    @functools.wraps(original)      # its signature stays the API's (tests read it)
    def recording_loads(text, *args, **kwargs):
        path = kwargs.get("path", args[3] if len(args) > 3 else "<string>")
        if isinstance(text, str):
            with open(record, "a") as f:
                f.write(json.dumps({"text": text, "path": str(path)}) + "\n")
        return original(text, *args, **kwargs)
    api.loads = fractalc.loads = recording_loads


class OpenCLWithoutMarker(AssertionError):
    pass


@pytest.fixture(autouse=True)
def _opencl_only_where_marked(request, monkeypatch, tmp_path_factory):
    """Out of reach for a test without the `opencl` marker: pyopencl's
    platforms, contexts, programs and buffers in this process (a device
    opened by an earlier test stays cached), and every driver for the
    processes it starts (an empty vendors folder, no bundled driver)."""
    if request.node.get_closest_marker("opencl"):
        return
    import pyopencl
    from fractalc import drivers

    def refused(*args, **kwargs):
        raise OpenCLWithoutMarker(f"{request.node.nodeid} uses OpenCL: mark it @pytest.mark.opencl")
    for name in ("get_platforms", "Context", "Program", "Buffer"):
        monkeypatch.setattr(pyopencl, name, refused)
    monkeypatch.setenv(drivers.VENDORS_ENVIRONMENT, str(tmp_path_factory.mktemp("no-opencl-vendors")))
    monkeypatch.setenv(drivers.SWITCH_ENVIRONMENT, "0")
