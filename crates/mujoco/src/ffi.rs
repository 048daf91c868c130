//! The plugin's C boundary, the crate's only `unsafe` and `extern "C"`: registration of
//! `thermovia.joint` with MuJoCo, its callbacks, and two functions that tell helpers the names.
//!
//! Every callback catches panics: an error reaches MuJoCo as `mju_warning` and a refused `init`
//! (MuJoCo then refuses the model), never as an unwind into C. Each `mjData` owns one [`Instance`]
//! per plugin instance (in `plugin_data`); nothing is global but the registration.

use std::ffi::{c_char, c_int, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::OnceLock;

use crate::config::{self, HEATER_KEY};
use crate::joint::{self, Joint, StepInputs, STATE_NAMES, STATE_SIZE};

#[allow(non_upper_case_globals, non_camel_case_types, non_snake_case, dead_code, clippy::all)]
mod sys {
    include!(concat!(env!("OUT_DIR"), "/mujoco.rs"));
}
use sys::{mjData, mjModel, mjpPlugin, mjtIntegrator, mjtJoint, mjtObj, mjtPluginCapabilityBit, mjtTrn};

pub const PLUGIN_NAME: &str = "thermovia.joint";
const PLUGIN_NAME_C: &CStr = c"thermovia.joint";

/// One plugin instance in one mjData.
struct Instance {
    joint: Joint,
    label: String,
    actuator: usize,
    qpos: usize,
    dof: usize,
    heater: Option<usize>,
    warned: bool,
}

fn warn(msg: &str) {
    let text = CString::new(msg.replace('\0', " ")).unwrap_or_default();
    // SAFETY: a printf-style call with a "%s" format and one NUL-terminated string.
    unsafe { sys::mju_warning(c"%s".as_ptr(), text.as_ptr()) };
}

/// The attribute names MuJoCo passes to the plugin, alive for the whole process.
struct Names {
    _owned: Vec<CString>,
    pointers: Vec<*const c_char>,
}
// SAFETY: the pointers point into `_owned`, which is never mutated or dropped after creation.
unsafe impl Send for Names {}
unsafe impl Sync for Names {}

fn attributes() -> &'static Names {
    static NAMES: OnceLock<Names> = OnceLock::new();
    NAMES.get_or_init(|| {
        let owned: Vec<CString> = config::keys().into_iter().map(|k| CString::new(k).expect("no NUL")).collect();
        let pointers = owned.iter().map(|c| c.as_ptr()).collect();
        Names { _owned: owned, pointers }
    })
}

fn comma_list(names: &[&str]) -> &'static CStr {
    Box::leak(CString::new(names.join(",")).expect("no NUL").into_boxed_c_str())
}

/// The `plugin_state` layout of one instance, comma-separated (`thermovia_joint.py` reads it).
#[no_mangle]
pub extern "C" fn thermovia_mujoco_state_names() -> *const c_char {
    static S: OnceLock<&'static CStr> = OnceLock::new();
    S.get_or_init(|| comma_list(&STATE_NAMES)).as_ptr()
}

/// The config keys the plugin declares, comma-separated (for suggestions on an unknown key).
#[no_mangle]
pub extern "C" fn thermovia_mujoco_config_keys() -> *const c_char {
    static S: OnceLock<&'static CStr> = OnceLock::new();
    S.get_or_init(|| comma_list(&config::keys())).as_ptr()
}

/// Reads `n` values of an mjModel/mjData array from `start`.
///
/// SAFETY: `p` must point to at least `start + n` values.
unsafe fn read<'a, T: Copy>(p: *const T, start: usize, n: usize) -> &'a [T] {
    std::slice::from_raw_parts(p.add(start), n)
}

unsafe fn name(m: *const mjModel, kind: mjtObj, id: usize) -> String {
    let p = sys::mj_id2name(m, kind as c_int, id as c_int);
    if p.is_null() {
        format!("#{id}")
    } else {
        CStr::from_ptr(p).to_string_lossy().into_owned()
    }
}

unsafe fn config_value(m: *const mjModel, instance: c_int, key: &str) -> Option<String> {
    let key = CString::new(key).ok()?;
    let p = sys::mj_getPluginConfig(m, instance, key.as_ptr());
    if p.is_null() {
        return None;
    }
    Some(CStr::from_ptr(p).to_string_lossy().into_owned())
}

/// Everything `init` checks; the error is the whole message.
unsafe fn make_instance(m: *const mjModel, instance: c_int) -> Result<Instance, String> {
    let mm = &*m;
    let nu = mm.nu as usize;
    let plugin_of = read(mm.actuator_plugin, 0, nu);
    let mine: Vec<usize> = (0..nu).filter(|&i| plugin_of[i] == instance).collect();
    let actuator = match mine.as_slice() {
        [a] => *a,
        [] => return Err(format!("{PLUGIN_NAME} instance {instance} drives no actuator: declare it as <actuator><plugin joint=… plugin=\"{PLUGIN_NAME}\">")),
        _ => return Err(format!("{PLUGIN_NAME} instance {instance} drives {} actuators; one instance is one joint", mine.len())),
    };
    let label = format!("{PLUGIN_NAME} (actuator '{}')", name(m, mjtObj::mjOBJ_ACTUATOR, actuator));
    let fail = |msg: String| Err(format!("{label}: {msg}"));
    let setup = match config::parse(&|k| config_value(m, instance, k)) {
        Ok(s) => s,
        Err(e) => return fail(e),
    };
    if read(mm.actuator_trntype, actuator, 1)[0] != mjtTrn::mjTRN_JOINT as c_int {
        return fail("its transmission must be a joint (joint=\"…\")".into());
    }
    let jnt = read(mm.actuator_trnid, 2 * actuator, 1)[0] as usize;
    let joint_name = name(m, mjtObj::mjOBJ_JOINT, jnt);
    if read(mm.jnt_type, jnt, 1)[0] != mjtJoint::mjJNT_HINGE as c_int {
        return fail(format!("joint '{joint_name}' is not a hinge: the ThermoVIA joint is rotary"));
    }
    let gear = read(mm.actuator_gear, 6 * actuator, 1)[0];
    if gear != 1.0 {
        return fail(format!("gear is {gear}: the joint is the ThermoVIA link, so gear must be 1"));
    }
    let qpos = read(mm.jnt_qposadr, jnt, 1)[0] as usize;
    let dof = read(mm.jnt_dofadr, jnt, 1)[0] as usize;
    let heater = match &setup.heater {
        None => None,
        Some(h) => {
            let c = CString::new(h.as_str()).map_err(|_| format!("{label}: {HEATER_KEY} holds a NUL"))?;
            let id = sys::mj_name2id(m, mjtObj::mjOBJ_ACTUATOR as c_int, c.as_ptr());
            if id < 0 {
                let names: Vec<String> =
                    (0..nu).filter(|&i| i != actuator).map(|i| name(m, mjtObj::mjOBJ_ACTUATOR, i)).collect();
                return fail(format!("{HEATER_KEY} = '{h}' names no actuator (the model has: {})", names.join(", ")));
            }
            Some(id as usize)
        }
    };
    let integrator = mm.opt.integrator;
    let supported = [mjtIntegrator::mjINT_EULER, mjtIntegrator::mjINT_IMPLICIT, mjtIntegrator::mjINT_IMPLICITFAST];
    if !supported.iter().any(|i| *i as c_int == integrator) {
        return fail(format!(
            "integrator {integrator} is not supported: use Euler, implicit or implicitfast (RK4 evaluates the \
             force four times per step, and the joint's step is taken once)"
        ));
    }
    let joint_damping = read(mm.dof_damping, dof, 1)[0];
    if setup.implicit_damping > joint_damping {
        return fail(format!(
            "implicit_damping {} is more than joint '{joint_name}''s damping {joint_damping}: the implicit share \
             is part of the joint's damping (damping=\"{}\" on the joint)",
            setup.implicit_damping, setup.implicit_damping
        ));
    }
    let h = mm.opt.timestep;
    let inertia = 1.0 / read(mm.dof_invweight0, dof, 1)[0];
    let (k, c) = joint::transmission_bounds(&setup.params, setup.ambient_temperature);
    let limit = joint::stability_limit(k, c, inertia, setup.implicit_damping);
    if !(h < limit) {
        let with_implicit = joint::stability_limit(k, c, inertia, c);
        return fail(format!(
            "timestep {h} s is at or above the coupling's stability limit {limit:.3e} s on joint '{joint_name}' \
             (effective inertia {inertia:.3e} kg.m2 at qpos0, transmission up to {k:.4} N.m/rad and {c:.4} \
             N.m.s/rad, implicit_damping {}). Take the transmission's damping implicitly (damping=\"{c:.4}\" on \
             the joint and <config key=\"implicit_damping\" value=\"{c:.4}\"/>, limit {with_implicit:.3e} s) or \
             use a smaller timestep",
            setup.implicit_damping
        ));
    }
    Ok(Instance { joint: Joint::new(&setup), label, actuator, qpos, dof, heater, warned: false })
}

unsafe fn instance_of<'a>(d: *mut mjData, instance: c_int) -> Option<&'a mut Instance> {
    let p = *(*d).plugin_data.add(instance as usize) as *mut Instance;
    p.as_mut()
}

unsafe fn state_of<'a>(m: *const mjModel, state: *mut f64, instance: c_int) -> Option<&'a mut [f64]> {
    let adr = *(*m).plugin_stateadr.add(instance as usize) as usize;
    let n = *(*m).plugin_statenum.add(instance as usize) as usize;
    (n == STATE_SIZE && !state.is_null()).then(|| std::slice::from_raw_parts_mut(state.add(adr), n))
}

fn guarded<R>(what: &str, fallback: R, f: impl FnOnce() -> R) -> R {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(p) => {
            let why = p
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| p.downcast_ref::<&str>().copied())
                .unwrap_or("unknown panic");
            warn(&format!("{PLUGIN_NAME}: {what} failed: {why}"));
            fallback
        }
    }
}

extern "C" fn nstate(_m: *const mjModel, _instance: c_int) -> c_int {
    STATE_SIZE as c_int
}

extern "C" fn init(m: *const mjModel, d: *mut mjData, instance: c_int) -> c_int {
    guarded("init", -1, || {
        // SAFETY: MuJoCo passes a valid model and data, and `instance` indexes plugin_data.
        unsafe {
            match make_instance(m, instance) {
                Ok(inst) => {
                    *(*d).plugin_data.add(instance as usize) = Box::into_raw(Box::new(inst)) as usize;
                    0
                }
                Err(msg) => {
                    warn(&msg);
                    -1
                }
            }
        }
    })
}

extern "C" fn destroy(d: *mut mjData, instance: c_int) {
    guarded("destroy", (), || {
        // SAFETY: the pointer was made by Box::into_raw in `init` and is cleared here, once.
        unsafe {
            let slot = (*d).plugin_data.add(instance as usize);
            let p = *slot as *mut Instance;
            if !p.is_null() {
                drop(Box::from_raw(p));
            }
            *slot = 0;
        }
    })
}

extern "C" fn copy(dest: *mut mjData, _m: *const mjModel, src: *const mjData, instance: c_int) {
    guarded("copy", (), || {
        // SAFETY: both mjData were made for this model, so both hold an Instance from `init`.
        unsafe {
            let s = *(*src).plugin_data.add(instance as usize) as *const Instance;
            if let (Some(dst), Some(s)) = (instance_of(dest, instance), s.as_ref()) {
                if !std::ptr::eq(dst, s) {
                    dst.joint.copy_from(&s.joint);
                }
            }
        }
    })
}

extern "C" fn reset(m: *const mjModel, plugin_state: *mut f64, plugin_data: *mut std::ffi::c_void, instance: c_int) {
    guarded("reset", (), || {
        // SAFETY: plugin_data is this instance's pointer from `init` (or null before it).
        unsafe {
            // MuJoCo passes this instance's own block of plugin_state here (not the whole array)
            let n = *(*m).plugin_statenum.add(instance as usize) as usize;
            let Some(inst) = (plugin_data as *mut Instance).as_mut() else { return };
            if n == STATE_SIZE && !plugin_state.is_null() {
                inst.joint.reset(std::slice::from_raw_parts_mut(plugin_state, n));
            }
        }
    })
}

extern "C" fn compute(m: *const mjModel, d: *mut mjData, instance: c_int, _capability: c_int) {
    guarded("compute", (), || {
        // SAFETY: valid model and data from MuJoCo; the addresses were checked against the model in `init`.
        unsafe {
            let (Some(inst), Some(state)) = (instance_of(d, instance), state_of(m, (*d).plugin_state, instance)) else {
                return;
            };
            let mm = &*m;
            let ctrl = |a: usize| {
                let mut x = *(*d).ctrl.add(a);
                if *mm.actuator_ctrllimited.add(a) != 0 {
                    x = x.clamp(*mm.actuator_ctrlrange.add(2 * a), *mm.actuator_ctrlrange.add(2 * a + 1));
                }
                x
            };
            let u = StepInputs {
                angle: *(*d).qpos.add(inst.qpos),
                speed: *(*d).qvel.add(inst.dof),
                motor_torque: ctrl(inst.actuator),
                heater_power: inst.heater.map_or(0.0, ctrl),
                step: mm.opt.timestep,
            };
            let force = match inst.joint.compute(state, u) {
                Ok(f) => f,
                Err(e) => {
                    if !inst.warned {
                        inst.warned = true;
                        warn(&format!(
                            "{} at t = {} s: {e}; the joint holds its state and last torque",
                            inst.label,
                            (*d).time
                        ));
                    }
                    state[joint::TORQUE_MEAN]
                }
            };
            *(*d).actuator_force.add(inst.actuator) = force;
        }
    })
}

extern "C" fn advance(m: *const mjModel, d: *mut mjData, instance: c_int) {
    guarded("advance", (), || {
        // SAFETY: as in `compute`.
        unsafe {
            let (Some(inst), Some(state)) = (instance_of(d, instance), state_of(m, (*d).plugin_state, instance)) else {
                return;
            };
            if let Err(e) = inst.joint.advance(state) {
                if !inst.warned {
                    inst.warned = true;
                    warn(&format!("{} at t = {} s: {e}; the joint holds its state", inst.label, (*d).time));
                }
            }
        }
    })
}

extern "C" fn register() {
    guarded("registration", (), || {
        let names = attributes();
        // SAFETY: mjp_defaultPlugin fills the struct; the name and attribute strings live for the process.
        unsafe {
            let mut p: mjpPlugin = std::mem::zeroed();
            sys::mjp_defaultPlugin(&mut p);
            p.name = PLUGIN_NAME_C.as_ptr();
            p.nattribute = names.pointers.len() as c_int;
            p.attributes = names.pointers.as_ptr();
            p.capabilityflags = mjtPluginCapabilityBit::mjPLUGIN_ACTUATOR as c_int;
            p.nstate = Some(nstate);
            p.init = Some(init);
            p.destroy = Some(destroy);
            p.copy = Some(copy);
            p.reset = Some(reset);
            p.compute = Some(compute);
            p.advance = Some(advance);
            sys::mjp_registerPlugin(&p);
        }
    })
}

/// Registers the plugin when the library is loaded (`mj_loadPluginLibrary`, or linked into a C++
/// program), as MuJoCo's own plugin libraries do.
#[used]
#[link_section = ".init_array"]
static REGISTER: extern "C" fn() = register;
