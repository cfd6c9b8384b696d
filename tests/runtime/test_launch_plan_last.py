"""``launch_plan`` tries the plan used last first: it must still notice another
device, another backend argument, new kernel options and new debug settings."""

import numpy as np

import kdsl as wp
from kdsl import config
from kdsl.runtime.launch import launch_plan


@wp.kernel
def _add(x: wp.array(dtype=float), s: float):
    x[wp.tid()] += s


def test_the_last_plan_serves_only_the_same_device_and_backend():
    cpu = launch_plan(_add, "cpu", None)
    assert launch_plan(_add, "cpu", None) is cpu
    assert launch_plan(_add, wp.get_device("cpu"), None) is cpu  # the Device itself
    interp = launch_plan(_add, "cpu", "interp")
    assert interp is not cpu and interp.backend.name == "interp"
    assert launch_plan(_add, "cpu", None) is cpu
    assert launch_plan(_add, "cpu", "interp") is interp


def test_the_last_plan_follows_options_and_settings(monkeypatch):
    x = wp.zeros(3, dtype=float, device="cpu")
    wp.launch(_add, 3, [x, 1.0], device="cpu")
    first = launch_plan(_add, "cpu", None)
    monkeypatch.setattr(config, "verify_fp", not config.verify_fp)
    checked = launch_plan(_add, "cpu", None)
    assert checked is not first and checked.settings != first.settings
    monkeypatch.undo()
    again = launch_plan(_add, "cpu", None)
    assert again.settings == first.settings
    _add.options["fast_math"] = True
    try:
        fast = launch_plan(_add, "cpu", None)
        assert fast is not again and fast.own == {"fast_math": True}
        wp.launch(_add, 3, [x, 2.0], device="cpu")
    finally:
        del _add.options["fast_math"]
    assert launch_plan(_add, "cpu", None).own == {}
    wp.launch(_add, 3, [x, 4.0], device="cpu")
    np.testing.assert_array_equal(x.numpy(), 7.0)
