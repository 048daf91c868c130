"""ThermoVIA joints in MuJoCo from Python: load the `thermovia.joint` actuator plugin, compile models
with a suggestion for a mistyped config key, and read or place a joint's state by name.

    import mujoco, thermovia_joint as tj
    tj.load_plugin()                              # target/release/libthermovia_mujoco.so
    m = tj.model_from_xml(xml)                    # or mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    d.ctrl[m.actuator("elbow").id] = 0.5          # motor torque, N·m
    mujoco.mj_step(m, d)
    tj.read(m, d, "elbow")["pcl_temperature"]     # K

The joint's state lives in `d.plugin_state` (so `mj_resetData`, `mj_copyData`, `mj_getState` with
`mjSTATE_PLUGIN` and `mujoco.rollout` carry it); its layout comes from the library itself
(`thermovia_mujoco_state_names`), the one place it is defined.
"""

from __future__ import annotations

import ctypes
import difflib
import os
import pathlib
import re

import mujoco
import numpy as np

PLUGIN = "thermovia.joint"
_ROOT = pathlib.Path(__file__).resolve().parents[3]
_loaded: dict = {}


def library_path() -> pathlib.Path:
    """$THERMOVIA_MUJOCO_PLUGIN, else the workspace's release build."""
    env = os.environ.get("THERMOVIA_MUJOCO_PLUGIN")
    return pathlib.Path(env) if env else _ROOT / "target" / "release" / "libthermovia_mujoco.so"


def load_plugin(path: str | os.PathLike | None = None) -> pathlib.Path:
    """Registers `thermovia.joint` with this process's MuJoCo (once)."""
    p = pathlib.Path(path) if path else library_path()
    if "path" not in _loaded:
        if not p.is_file():
            raise FileNotFoundError(f"{p}: build it with `cargo build --release -p thermovia-mujoco`")
        mujoco.mj_loadPluginLibrary(str(p))
        lib = ctypes.CDLL(str(p))
        for f in ("thermovia_mujoco_state_names", "thermovia_mujoco_config_keys"):
            getattr(lib, f).restype = ctypes.c_char_p
        _loaded["path"] = p
        _loaded["names"] = lib.thermovia_mujoco_state_names().decode().split(",")
        _loaded["keys"] = lib.thermovia_mujoco_config_keys().decode().split(",")
    return _loaded["path"]


def state_names() -> list[str]:
    load_plugin()
    return list(_loaded["names"])


def config_keys() -> list[str]:
    load_plugin()
    return list(_loaded["keys"])


def _explain(err: Exception) -> Exception:
    """MuJoCo's compiler refuses an unknown config key before the plugin sees it; add the key it
    most likely meant."""
    text = str(err)
    m = re.search(r"unrecognized attribute 'plugin:([^']*)' for plugin " + re.escape(PLUGIN), text)
    if not m:
        return err
    close = difflib.get_close_matches(m.group(1), config_keys(), n=1, cutoff=0.6)
    hint = f" (did you mean '{close[0]}'?)" if close else ""
    return ValueError(f"{text}{hint}")


def model_from_xml(xml: str) -> mujoco.MjModel:
    load_plugin()
    try:
        return mujoco.MjModel.from_xml_string(xml)
    except ValueError as e:
        raise _explain(e) from None


def model_from_path(path: str | os.PathLike) -> mujoco.MjModel:
    load_plugin()
    try:
        return mujoco.MjModel.from_xml_path(str(path))
    except ValueError as e:
        raise _explain(e) from None


def _slice(m, actuator: str | int) -> slice:
    a = m.actuator(actuator).id
    instance = int(m.actuator_plugin[a])
    if instance < 0:
        raise KeyError(f"actuator {actuator!r} is not a {PLUGIN} actuator")
    adr = int(m.plugin_stateadr[instance])
    n = int(m.plugin_statenum[instance])
    if n != len(state_names()):
        raise RuntimeError(f"actuator {actuator!r}: {n} state numbers, the library names {len(state_names())}")
    return slice(adr, adr + n)


def read(m, d, actuator: str | int) -> dict:
    """The joint's state and outputs after the last step, by name (motor_angle, pcl_temperature,
    effective_stiffness, transmitted_torque_mean, ...)."""
    values = d.plugin_state[_slice(m, actuator)]
    return dict(zip(state_names(), (float(v) for v in values)))


def index(m, actuator: str | int, name: str) -> int:
    """Where `name` of this joint sits in `d.plugin_state` (for reading many steps fast)."""
    return _slice(m, actuator).start + state_names().index(name)


def set_motor(m, d, actuator: str | int, angle: float, speed: float = 0.0) -> None:
    """Places the motor (rad, rad/s) instead of aligning it with the joint at the next step."""
    s = _slice(m, actuator)
    names = state_names()
    state = d.plugin_state[s]
    state[names.index("motor_angle")] = angle
    state[names.index("motor_speed")] = speed
    state[names.index("motor_placed")] = 1.0
    d.plugin_state[s] = state


FULL = mujoco.mjtState.mjSTATE_FULLPHYSICS


def full_state(m, d):
    """The state `mujoco.rollout` starts from (time, qpos, qvel, act, plugin_state)."""
    x = np.empty(mujoco.mj_stateSize(m, FULL))
    mujoco.mj_getState(m, d, x, FULL)
    return x


def step_serially(m, d, initial, control):
    """What `mujoco.rollout(m, d, initial, control)` returns, by mj_step from Python: the state after
    every step of every copy, (copies, steps, state size)."""
    out = np.empty((len(initial), control.shape[1], len(initial[0])))
    for c in range(len(initial)):
        mujoco.mj_setState(m, d, initial[c], FULL)
        for i in range(control.shape[1]):
            d.ctrl[:] = control[c, i]
            mujoco.mj_step(m, d)
            mujoco.mj_getState(m, d, out[c, i], FULL)
    return out
