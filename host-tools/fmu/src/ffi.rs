//! The C boundary: every FMI 2.0 function under its standard name. Each
//! checks its pointers, catches panics (a panic becomes `fmi2Fatal` and a
//! logger message, never an unwind into the importer) and hands the work
//! to [`crate::instance`]. The model-exchange functions, directional
//! derivatives, FMU state get/set and input derivatives are exported too
//! (an importer may resolve them all) and return `fmi2Error`.
//!
//! The contract of each function (pointer validity, array lengths) is the
//! FMI 2.0 standard's, section 2.1 and 4.2; hence no per-function safety
//! section.
#![allow(non_snake_case, non_camel_case_types, clippy::missing_safety_doc)]

use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};

use crate::instance::{Instance, Phase};
use crate::table::{Kind, Val};

pub type fmi2Component = *mut c_void;
pub type fmi2Status = c_int;
pub type fmi2Boolean = c_int;
pub type fmi2ValueReference = u32;
pub type fmi2String = *const c_char;

pub const OK: fmi2Status = 0;
pub const WARNING: fmi2Status = 1;
pub const DISCARD: fmi2Status = 2;
pub const ERROR: fmi2Status = 3;
pub const FATAL: fmi2Status = 4;
const CO_SIMULATION: c_int = 1;
const LAST_SUCCESSFUL_TIME: c_int = 2;
const TERMINATED: c_int = 3;

type Logger = Option<
    unsafe extern "C" fn(
        env: *mut c_void,
        instance: fmi2String,
        status: fmi2Status,
        category: fmi2String,
        message: fmi2String,
        ...
    ),
>;

/// `fmi2CallbackFunctions`: only the logger and its environment are used
/// (the FMU allocates with Rust's allocator: `canNotUseMemoryManagementFunctions`).
#[repr(C)]
pub struct CallbackFunctions {
    logger: Logger,
    allocate_memory: *const c_void,
    free_memory: *const c_void,
    step_finished: *const c_void,
    environment: *mut c_void,
}

/// What an `fmi2Component` points to.
struct Component {
    name: CString,
    logger: Logger,
    environment: *mut c_void,
    instance: Instance,
}

impl Component {
    fn log(&self, status: fmi2Status, message: &str) {
        log_to(self.logger, self.environment, &self.name, status, message);
    }
}

fn log_to(logger: Logger, env: *mut c_void, name: &CStr, status: fmi2Status, message: &str) {
    let Some(logger) = logger else { return };
    // The message is a printf format: a literal % is doubled.
    let text = CString::new(message.replace('%', "%%").replace('\0', " ")).unwrap_or_default();
    let category = if status >= ERROR { c"logStatusError" } else { c"logAll" };
    // SAFETY: the importer's logger, called with NUL-terminated strings that outlive the call.
    unsafe { logger(env, name.as_ptr(), status, category.as_ptr(), text.as_ptr()) };
}

fn panic_text(p: &(dyn std::any::Any + Send)) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".into())
}

/// Runs `f` on the component behind `c`: null is an error, a refusal is
/// logged as `fmi2Error`, a panic as `fmi2Fatal` (the instance is then
/// failed until a reset).
unsafe fn with(
    c: fmi2Component,
    call: &str,
    f: impl FnOnce(&mut Component) -> Result<fmi2Status, String>,
) -> fmi2Status {
    if c.is_null() {
        return ERROR;
    }
    // SAFETY: a non-null component is one fmi2Instantiate returned (the standard's contract).
    let comp = unsafe { &mut *(c as *mut Component) };
    match catch_unwind(AssertUnwindSafe(|| f(comp))) {
        Ok(Ok(status)) => status,
        Ok(Err(message)) => {
            comp.log(ERROR, &format!("{call}: {message}"));
            ERROR
        }
        Err(p) => {
            comp.instance.fail();
            comp.log(FATAL, &format!("{call}: internal error: {}", panic_text(p.as_ref())));
            FATAL
        }
    }
}

/// A slice from an importer's array; null with a non-zero length is refused.
unsafe fn slice<'a, T>(p: *const T, n: usize) -> Result<&'a [T], String> {
    if n == 0 {
        Ok(&[])
    } else if p.is_null() {
        Err("null array".into())
    } else {
        // SAFETY: the importer passes n valid elements (the standard's contract).
        Ok(unsafe { std::slice::from_raw_parts(p, n) })
    }
}

unsafe fn slice_mut<'a, T>(p: *mut T, n: usize) -> Result<&'a mut [T], String> {
    if n == 0 {
        Ok(&mut [])
    } else if p.is_null() {
        Err("null array".into())
    } else {
        // SAFETY: as `slice`.
        Ok(unsafe { std::slice::from_raw_parts_mut(p, n) })
    }
}

unsafe fn text(s: fmi2String) -> Option<String> {
    // SAFETY: a non-null fmi2String is NUL-terminated (the standard's contract).
    (!s.is_null()).then(|| unsafe { CStr::from_ptr(s) }.to_string_lossy().into_owned())
}

#[no_mangle]
pub extern "C" fn fmi2GetTypesPlatform() -> *const c_char {
    c"default".as_ptr()
}

#[no_mangle]
pub extern "C" fn fmi2GetVersion() -> *const c_char {
    c"2.0".as_ptr()
}

#[no_mangle]
pub unsafe extern "C" fn fmi2Instantiate(
    instance_name: fmi2String,
    fmu_type: c_int,
    guid: fmi2String,
    resource_location: fmi2String,
    functions: *const CallbackFunctions,
    _visible: fmi2Boolean,
    _logging_on: fmi2Boolean,
) -> fmi2Component {
    let (logger, env) = if functions.is_null() {
        (None, std::ptr::null_mut())
    } else {
        // SAFETY: non-null callbacks point to the importer's struct.
        let f = unsafe { &*functions };
        (f.logger, f.environment)
    };
    let name = unsafe { text(instance_name) }.unwrap_or_default();
    let cname = CString::new(name.replace('\0', " ")).unwrap_or_default();
    let made = catch_unwind(AssertUnwindSafe(|| -> Result<Instance, String> {
        if fmu_type != CO_SIMULATION {
            return Err("this FMU is for co-simulation only (fmi2CoSimulation)".into());
        }
        let location = unsafe { text(resource_location) }.ok_or("no resource location")?;
        let (model, json) = crate::description::read_resources(&location)?;
        let expected = crate::description::guid(&json);
        match unsafe { text(guid) } {
            Some(g) if g == expected => {}
            g => return Err(format!("GUID {g:?} does not match this FMU's {expected}")),
        }
        Instance::new(model)
    }));
    match made {
        Ok(Ok(instance)) => Box::into_raw(Box::new(Component {
            name: cname,
            logger,
            environment: env,
            instance,
        })) as fmi2Component,
        Ok(Err(message)) => {
            log_to(logger, env, &cname, ERROR, &format!("fmi2Instantiate: {message}"));
            std::ptr::null_mut()
        }
        Err(p) => {
            let message = format!("fmi2Instantiate: internal error: {}", panic_text(p.as_ref()));
            log_to(logger, env, &cname, FATAL, &message);
            std::ptr::null_mut()
        }
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2FreeInstance(c: fmi2Component) {
    if !c.is_null() {
        // SAFETY: made by Box::into_raw in fmi2Instantiate, freed once (the standard's contract).
        let _ = catch_unwind(|| drop(unsafe { Box::from_raw(c as *mut Component) }));
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetDebugLogging(
    c: fmi2Component,
    _logging_on: fmi2Boolean,
    _n: usize,
    _categories: *const fmi2String,
) -> fmi2Status {
    unsafe { with(c, "fmi2SetDebugLogging", |_| Ok(OK)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetupExperiment(
    c: fmi2Component,
    _tolerance_defined: fmi2Boolean,
    _tolerance: f64,
    start_time: f64,
    stop_time_defined: fmi2Boolean,
    stop_time: f64,
) -> fmi2Status {
    unsafe {
        with(c, "fmi2SetupExperiment", |comp| {
            let stop = (stop_time_defined != 0).then_some(stop_time);
            comp.instance.setup_experiment(start_time, stop).map(|()| OK)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2EnterInitializationMode(c: fmi2Component) -> fmi2Status {
    unsafe {
        with(c, "fmi2EnterInitializationMode", |comp| {
            comp.instance.enter_initialization().map(|()| OK)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2ExitInitializationMode(c: fmi2Component) -> fmi2Status {
    unsafe {
        with(c, "fmi2ExitInitializationMode", |comp| {
            comp.instance.exit_initialization().map(|()| OK)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2Terminate(c: fmi2Component) -> fmi2Status {
    unsafe { with(c, "fmi2Terminate", |comp| comp.instance.terminate().map(|()| OK)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2Reset(c: fmi2Component) -> fmi2Status {
    unsafe {
        with(c, "fmi2Reset", |comp| {
            comp.instance.reset();
            Ok(OK)
        })
    }
}

/// Reads `vr` into `out` through `conv`.
unsafe fn get_values<T>(
    c: fmi2Component,
    call: &str,
    vr: *const fmi2ValueReference,
    n: usize,
    out: *mut T,
    kind: Kind,
    conv: fn(Val) -> T,
) -> fmi2Status {
    unsafe {
        with(c, call, |comp| {
            let (vr, out) = (slice(vr, n)?, slice_mut(out, n)?);
            for (r, o) in vr.iter().zip(out.iter_mut()) {
                *o = conv(comp.instance.get(*r, kind)?);
            }
            Ok(OK)
        })
    }
}

unsafe fn set_values<T: Copy>(
    c: fmi2Component,
    call: &str,
    vr: *const fmi2ValueReference,
    n: usize,
    values: *const T,
    conv: fn(T) -> Val,
) -> fmi2Status {
    unsafe {
        with(c, call, |comp| {
            let (vr, values) = (slice(vr, n)?, slice(values, n)?);
            for (r, v) in vr.iter().zip(values) {
                comp.instance.set(*r, conv(*v))?;
            }
            Ok(OK)
        })
    }
}

fn real(v: Val) -> f64 {
    match v {
        Val::Real(x) => x,
        _ => f64::NAN,
    }
}

fn integer(v: Val) -> c_int {
    match v {
        Val::Integer(x) => x,
        _ => 0,
    }
}

fn boolean(v: Val) -> fmi2Boolean {
    c_int::from(matches!(v, Val::Boolean(true)))
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetReal(c: fmi2Component, vr: *const u32, n: usize, value: *mut f64) -> fmi2Status {
    unsafe { get_values(c, "fmi2GetReal", vr, n, value, Kind::Real, real) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetInteger(c: fmi2Component, vr: *const u32, n: usize, value: *mut c_int) -> fmi2Status {
    unsafe { get_values(c, "fmi2GetInteger", vr, n, value, Kind::Integer, integer) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetBoolean(c: fmi2Component, vr: *const u32, n: usize, value: *mut c_int) -> fmi2Status {
    unsafe { get_values(c, "fmi2GetBoolean", vr, n, value, Kind::Boolean, boolean) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetReal(c: fmi2Component, vr: *const u32, n: usize, value: *const f64) -> fmi2Status {
    unsafe { set_values(c, "fmi2SetReal", vr, n, value, Val::Real) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetInteger(c: fmi2Component, vr: *const u32, n: usize, value: *const c_int) -> fmi2Status {
    unsafe { set_values(c, "fmi2SetInteger", vr, n, value, Val::Integer) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetBoolean(c: fmi2Component, vr: *const u32, n: usize, value: *const c_int) -> fmi2Status {
    unsafe { set_values(c, "fmi2SetBoolean", vr, n, value, |b| Val::Boolean(b != 0)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetString(
    c: fmi2Component,
    _vr: *const u32,
    n: usize,
    _value: *mut fmi2String,
) -> fmi2Status {
    unsafe { no_strings(c, "fmi2GetString", n) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetString(
    c: fmi2Component,
    _vr: *const u32,
    n: usize,
    _value: *const fmi2String,
) -> fmi2Status {
    unsafe { no_strings(c, "fmi2SetString", n) }
}

unsafe fn no_strings(c: fmi2Component, call: &str, n: usize) -> fmi2Status {
    unsafe {
        with(c, call, |_| {
            if n == 0 {
                Ok(OK)
            } else {
                Err("this FMU has no String variables".into())
            }
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2DoStep(c: fmi2Component, t: f64, h: f64, _no_set_prior: fmi2Boolean) -> fmi2Status {
    unsafe { with(c, "fmi2DoStep", |comp| comp.instance.do_step(t, h).map(|()| OK)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetStatus(c: fmi2Component, _kind: c_int, _value: *mut fmi2Status) -> fmi2Status {
    unsafe { with(c, "fmi2GetStatus", |_| Ok(DISCARD)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetRealStatus(c: fmi2Component, kind: c_int, value: *mut f64) -> fmi2Status {
    unsafe {
        with(c, "fmi2GetRealStatus", |comp| {
            let out = slice_mut(value, 1)?;
            if kind != LAST_SUCCESSFUL_TIME {
                return Ok(DISCARD);
            }
            out[0] = comp.instance.time_s();
            Ok(OK)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetIntegerStatus(c: fmi2Component, _kind: c_int, _value: *mut c_int) -> fmi2Status {
    unsafe { with(c, "fmi2GetIntegerStatus", |_| Ok(DISCARD)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetBooleanStatus(c: fmi2Component, kind: c_int, value: *mut c_int) -> fmi2Status {
    unsafe {
        with(c, "fmi2GetBooleanStatus", |comp| {
            let out = slice_mut(value, 1)?;
            if kind != TERMINATED {
                return Ok(DISCARD);
            }
            out[0] = c_int::from(comp.instance.phase() == Phase::Terminated);
            Ok(OK)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetStringStatus(c: fmi2Component, _kind: c_int, _value: *mut fmi2String) -> fmi2Status {
    unsafe { with(c, "fmi2GetStringStatus", |_| Ok(DISCARD)) }
}

/// The functions this FMU does not support: each logs and returns `fmi2Error`.
macro_rules! unsupported {
    ($($name:ident($($arg:ident: $ty:ty),*)),* $(,)?) => {
        $(
            #[no_mangle]
            pub unsafe extern "C" fn $name(c: fmi2Component $(, $arg: $ty)*) -> fmi2Status {
                $(let _ = $arg;)*
                unsafe {
                    with(c, stringify!($name), |_| {
                        Err("not supported by this FMU (co-simulation only, no FMU state, no derivatives)".into())
                    })
                }
            }
        )*
    };
}

unsupported! {
    fmi2GetFMUstate(s: *mut *mut c_void),
    fmi2SetFMUstate(s: *mut c_void),
    fmi2FreeFMUstate(s: *mut *mut c_void),
    fmi2SerializedFMUstateSize(s: *mut c_void, size: *mut usize),
    fmi2SerializeFMUstate(s: *mut c_void, bytes: *mut c_char, size: usize),
    fmi2DeSerializeFMUstate(bytes: *const c_char, size: usize, s: *mut *mut c_void),
    fmi2GetDirectionalDerivative(
        unknown: *const u32, n_unknown: usize, known: *const u32, n_known: usize, dv_known: *const f64, dv_unknown: *mut f64
    ),
    fmi2SetRealInputDerivatives(vr: *const u32, n: usize, order: *const c_int, value: *const f64),
    fmi2GetRealOutputDerivatives(vr: *const u32, n: usize, order: *const c_int, value: *mut f64),
    fmi2CancelStep(),
    fmi2EnterEventMode(),
    fmi2NewDiscreteStates(info: *mut c_void),
    fmi2EnterContinuousTimeMode(),
    fmi2CompletedIntegratorStep(no_set_prior: fmi2Boolean, enter_event_mode: *mut c_int, terminate: *mut c_int),
    fmi2SetTime(t: f64),
    fmi2SetContinuousStates(x: *const f64, n: usize),
    fmi2GetDerivatives(dx: *mut f64, n: usize),
    fmi2GetEventIndicators(z: *mut f64, n: usize),
    fmi2GetContinuousStates(x: *mut f64, n: usize),
    fmi2GetNominalsOfContinuousStates(x: *mut f64, n: usize),
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    static LOG: Mutex<Vec<(fmi2Status, String)>> = Mutex::new(Vec::new());

    /// A logger that takes no further arguments: called through the
    /// variadic type with none, as the FMU does (Rust cannot define a
    /// C-variadic function on stable).
    unsafe extern "C" fn logger(_: *mut c_void, _: fmi2String, status: fmi2Status, _: fmi2String, m: fmi2String) {
        let text = unsafe { CStr::from_ptr(m) }.to_string_lossy().into_owned();
        LOG.lock().unwrap().push((status, text));
    }

    fn last_log() -> (fmi2Status, String) {
        LOG.lock().unwrap().last().cloned().unwrap()
    }

    /// A resources folder with the default configuration: (its URI, the GUID).
    fn resources() -> (CString, CString) {
        let dir = std::env::temp_dir().join(format!("hammer-fmu-ffi-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let json = crate::description::config_json(&hammer_sim::SimConfig::default()).unwrap();
        std::fs::write(dir.join(crate::description::CONFIG_RESOURCE), &json).unwrap();
        let uri = format!("file://{}", dir.display());
        (
            CString::new(uri).unwrap(),
            CString::new(crate::description::guid(&json)).unwrap(),
        )
    }

    /// Null pointers, a wrong GUID, model exchange and a panic come back
    /// as statuses (and logger messages), never as a crash or an unwind.
    #[test]
    fn the_boundary_turns_bad_calls_and_panics_into_statuses() {
        let (uri, guid) = resources();
        let callbacks = CallbackFunctions {
            // SAFETY: the same fixed arguments; the FMU passes no variadic ones.
            logger: Some(unsafe {
                std::mem::transmute::<
                    unsafe extern "C" fn(*mut c_void, fmi2String, fmi2Status, fmi2String, fmi2String),
                    unsafe extern "C" fn(*mut c_void, fmi2String, fmi2Status, fmi2String, fmi2String, ...),
                >(logger)
            }),
            allocate_memory: std::ptr::null(),
            free_memory: std::ptr::null(),
            step_finished: std::ptr::null(),
            environment: std::ptr::null_mut(),
        };
        unsafe {
            let name = c"test".as_ptr();
            let me = fmi2Instantiate(name, 0, guid.as_ptr(), uri.as_ptr(), &callbacks, 0, 0);
            assert!(me.is_null());
            assert!(last_log().1.contains("co-simulation only"), "{:?}", last_log());
            let wrong = fmi2Instantiate(name, 1, c"{0}".as_ptr(), uri.as_ptr(), &callbacks, 0, 0);
            assert!(wrong.is_null() && last_log().1.contains("GUID"));
            assert!(fmi2Instantiate(name, 1, guid.as_ptr(), std::ptr::null(), &callbacks, 0, 0).is_null());

            assert_eq!(fmi2DoStep(std::ptr::null_mut(), 0.0, 1e-5, 0), ERROR);
            let c = fmi2Instantiate(name, 1, guid.as_ptr(), uri.as_ptr(), &callbacks, 0, 0);
            assert!(!c.is_null());
            assert_eq!(fmi2GetReal(c, std::ptr::null(), 1, std::ptr::null_mut()), ERROR);
            assert!(last_log().1.contains("null array"));
            assert_eq!(fmi2GetDerivatives(c, std::ptr::null_mut(), 0), ERROR);
            assert_eq!(fmi2DoStep(c, 0.0, 1e-5, 0), ERROR, "before initialisation");

            let status = with(c, "fmi2Test", |_| panic!("a bug"));
            assert_eq!(status, FATAL);
            assert_eq!(last_log(), (FATAL, "fmi2Test: internal error: a bug".to_string()));
            assert_eq!(fmi2EnterInitializationMode(c), ERROR, "failed until reset");
            assert_eq!(fmi2Reset(c), OK);
            assert_eq!(fmi2SetupExperiment(c, 0, 0.0, 0.0, 1, 0.01), OK);
            assert_eq!(fmi2EnterInitializationMode(c), OK);
            assert_eq!(fmi2ExitInitializationMode(c), OK);
            assert_eq!(fmi2DoStep(c, 0.0, 1e-3, 0), OK);
            let mut t = 0.0;
            assert_eq!(fmi2GetRealStatus(c, LAST_SUCCESSFUL_TIME, &mut t), OK);
            assert_eq!(t, 1e-3);
            fmi2FreeInstance(c);
        }
    }
}
