"""mpm.launch.Launches: a recorded launch repacks what changed and gives
what wp.launch gives."""

import numpy as np
import warp as wp

from helpers import DEVICE
from mpm.launch import Launches


@wp.struct
class Offset:
    shift: wp.float32


@wp.kernel
def affine(x: wp.array(dtype=wp.float32), a: wp.float32, v: wp.vec2, o: Offset, out: wp.array(dtype=wp.float32)):
    i = wp.tid()
    out[i] = a * x[i] + v[0] + o.shift


def test_recorded_launches_follow_every_changed_argument():
    """out = a x + v_0 + o.shift over dim entries, through Launches and
    through wp.launch, while each argument changes in turn: a new array, a
    new scalar, a new vector, a struct field changed in place, a new size."""
    with wp.ScopedDevice(DEVICE):
        x1 = wp.array(np.arange(8, dtype=np.float32))
        x2 = wp.array(np.arange(8, dtype=np.float32) * 10.0)
        o = Offset()
        o.shift = 0.5
        calls = [(x1, 2.0, wp.vec2(1.0, 0.0), 8), (x1, 2.0, wp.vec2(1.0, 0.0), 8), (x2, 2.0, wp.vec2(1.0, 0.0), 8),
                 (x2, 3.0, wp.vec2(1.0, 0.0), 8), (x2, 3.0, wp.vec2(-1.0, 0.0), 8), ("shift", 3.0, wp.vec2(-1.0, 0.0), 8),
                 (x1, 3.0, wp.vec2(-1.0, 0.0), 5), (x1, 3.0, wp.vec2(-1.0, 0.0), 0), (x1, 3.0, wp.vec2(-1.0, 0.0), 8)]
        launches = Launches(DEVICE)
        x = x1
        for arg, a, v, n in calls:
            if arg == "shift":
                o.shift = 4.0  # a struct changed in place
            else:
                x = arg
            got = wp.full(8, -7.0, dtype=wp.float32)
            want = wp.full(8, -7.0, dtype=wp.float32)
            launches(affine, n, [x, wp.float32(a), v, o, got])
            wp.launch(affine, n, inputs=[x, wp.float32(a), v, o, want])
            np.testing.assert_array_equal(got.numpy(), want.numpy())
            expected = np.full(8, -7.0, np.float32)
            expected[:n] = a * x.numpy()[:n] + v[0] + o.shift
            np.testing.assert_array_equal(got.numpy(), expected)
