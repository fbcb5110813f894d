"""The physics presses' compiled loop (numba): a batch of presses, one after the other, each
stepped by MuJoCo's own ``mj_step`` (called from the loop through MuJoCo's library) with its
contact set again, at every step it is due, where the fingertip moved: the rule and the
operations of :meth:`runner.world.physics.Scene.probe_stepwise`, without Python between the
steps. Imported at the first batch of presses (numba takes a while to load); a press's
readings depend on nothing but its own start (each starts from MuJoCo's reset state).
"""

from __future__ import annotations

import ctypes
import functools
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
from numba import carray, njit, types
from numba.extending import intrinsic


@intrinsic
def _doubles_at(typingctx: Any, address: Any) -> Any:
    """The array of doubles at a memory address (an integer): a field of MuJoCo's model or
    data, whose place the bindings' arrays give (``array.ctypes.data``)."""
    if not isinstance(address, types.Integer):
        return None
    signature = types.CPointer(types.float64)(address)

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        return builder.inttoptr(args[0], context.get_value_type(sig.return_type))

    return signature, codegen


#: (for the type checker, which reads the intrinsic's typing signature as its call's)
_array_at: Any = _doubles_at


@functools.cache
def mujoco_library() -> tuple[Any, Any]:
    """MuJoCo's ``mj_step`` and ``mj_resetData``, from the library the bindings loaded (the
    same file, so the same copy of it in the process), each taking a model and a data by
    address."""
    import mujoco

    folder = Path(mujoco.__file__).parent
    patterns = {"win32": ("mujoco*.dll",), "darwin": ("libmujoco*.dylib",)}.get(
        sys.platform, ("libmujoco.so*",))
    found = sorted(path for pattern in patterns for path in folder.glob(pattern))
    if not found:
        from bayesprog import BayesprogError

        raise BayesprogError(f"MuJoCo's library was not found beside its Python bindings in "
                             f"{folder}: reinstall the physics extra (pip install "
                             "'bayesprog[physics]')")
    library = ctypes.CDLL(str(found[0]))
    functions = []
    for name in ("mj_step", "mj_resetData"):
        function = getattr(library, name)
        function.argtypes, function.restype = (ctypes.c_void_p, ctypes.c_void_p), None
        functions.append(function)
    return functions[0], functions[1]


@njit(cache=True, nogil=True)
def contact_at(x: float, y: float, depth: float, fingertip: float, cell: float, nx: int,
               ny: int, disc: np.ndarray, cell_contact: np.ndarray, materials: np.ndarray,
               variants: np.ndarray, slopes: np.ndarray, spacing: float, samples: int,
               least_friction: float) -> tuple[float, float, float]:
    """(stiffness, damping, friction) under a fingertip at (``x``, ``y``) pressed ``depth``
    in, as :meth:`runner.world.physics.Scene.contact` computes it: each cell's under the
    points ``disc`` of the contact disc (radius sqrt(R depth), at least a tenth of the
    fingertip's) averaged, the friction raised by the relief's slope under the centre."""
    radius = max(math.sqrt(fingertip * max(depth, 0.0)), fingertip / 10)
    k = b = mu = 0.0
    for p in range(disc.shape[0]):
        px = min(max((x + radius * disc[p, 0]) // cell, 0.0), nx - 1.0)
        py = min(max((y + radius * disc[p, 1]) // cell, 0.0), ny - 1.0)
        under = int(px) * ny + int(py)
        k += cell_contact[under, 0]
        b += cell_contact[under, 1]
        mu += cell_contact[under, 2]
    count = disc.shape[0]
    ix = min(max(int(x // cell), 0), nx - 1)
    iy = min(max(int(y // cell), 0), ny - 1)
    centre = ix * ny + iy
    u = int((x - ix * cell) / spacing) % samples
    v = int((y - iy * cell) / spacing) % samples
    slope = slopes[materials[centre], variants[centre], u, v]
    return k / count, b / count, max(mu / count + slope, least_friction)


@njit(cache=True, nogil=True)
def press_batch(step: Any, reset: Any, model: int, data: int, fields: np.ndarray,
                nsensordata: int, x0: np.ndarray, y0: np.ndarray, start_height: float,
                approach_damping: float, z_damping: float, force: float, path: np.ndarray,
                tip_mass: float, half_sample: float, fingertip: float, cell: float, nx: int,
                ny: int, disc: np.ndarray, cell_contact: np.ndarray, materials: np.ndarray,
                variants: np.ndarray, slopes: np.ndarray, spacing: float, samples: int,
                least_friction: float, readings: np.ndarray) -> None:
    """Press i from (``x0[i]``, ``y0[i]``, ``start_height``): MuJoCo's data reset, the z axis
    damped for the approach until the fingertip touches, the x stage's target moved along
    ``path`` (one offset per step), and before every step the contact set again where the
    fingertip moved half a relief sample along x or its depth changed by a twentieth;
    ``readings[i, k]`` gets every sensor after step k. ``fields`` holds the addresses of the
    model's and the data's arrays the loop reads and writes: qpos, ctrl, sensordata (of the
    data), the contact pair's solref and friction, the joints' damping (of the model)."""
    qpos, ctrl = carray(_array_at(fields[0]), 3), carray(_array_at(fields[1]), 3)
    sensed = carray(_array_at(fields[2]), nsensordata)
    solref, friction = carray(_array_at(fields[3]), 2), carray(_array_at(fields[4]), 2)
    damping = carray(_array_at(fields[5]), 3)
    for i in range(x0.size):
        reset(model, data)
        qpos[0], qpos[1], qpos[2] = x0[i], y0[i], start_height
        damping[2] = approach_damping
        ctrl[0], ctrl[1], ctrl[2] = x0[i], y0[i], -force
        at_x, at_depth = np.inf, np.inf  # where the contact was last set
        touching = False
        for k in range(path.size):
            x, y, z = qpos[0], qpos[1], qpos[2]
            if not touching and sensed[0] > 0:
                damping[2], touching = z_damping, True
            depth = fingertip - z
            if abs(x - at_x) > half_sample or abs(depth - at_depth) > 0.05 * abs(at_depth) \
                    + 1e-5:
                stiffness, damped, mu = contact_at(
                    x, y, depth, fingertip, cell, nx, ny, disc, cell_contact, materials,
                    variants, slopes, spacing, samples, least_friction)
                # MuJoCo's soft contact: with impedance d, a reference stiffness of K / (2 m)
                # settles a press of F newtons at F / K metres (elliptic cones)
                solref[0], solref[1] = -stiffness / (2 * tip_mass), -damped / (2 * tip_mass)
                friction[0], friction[1] = mu, mu
                at_x, at_depth = x, depth
            ctrl[0] = x0[i] + path[k]
            step(model, data)
            readings[i, k, :] = sensed
