//! A foreign FMU's shared library, called: `dlopen`, every FMI 2.0
//! co-simulation function the import needs resolved up front (a missing one
//! is named), one instance. Only the worker process ([`super::worker`])
//! uses this: whatever the library does wrong (crashes, hangs, corrupts
//! memory) happens there, not in the host.
#![allow(non_snake_case)]

use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::path::Path;

type Component = *mut c_void;
type Status = c_int;
type Vr = u32;

/// The statuses a call can return (FMI 2.0, section 2.1.3).
pub fn status_name(s: Status) -> &'static str {
    match s {
        0 => "fmi2OK",
        1 => "fmi2Warning",
        2 => "fmi2Discard",
        3 => "fmi2Error",
        4 => "fmi2Fatal",
        5 => "fmi2Pending",
        _ => "an unknown status",
    }
}

/// The logger. FMI declares it variadic (a printf format and its
/// arguments); stable Rust cannot define a variadic function, and on the
/// x86-64 System V ABI a variadic call reaches a non-variadic callee with
/// its fixed arguments intact, so the format is printed unformatted.
unsafe extern "C" fn logger(
    _env: *mut c_void,
    instance: *const c_char,
    status: Status,
    category: *const c_char,
    message: *const c_char,
) {
    let text = |p: *const c_char| {
        if p.is_null() {
            String::new()
        } else {
            // SAFETY: the FMU passes NUL-terminated strings (the standard's contract).
            unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
        }
    };
    let (category, message) = (text(category), text(message));
    eprintln!(
        "fmu log: {} [{}] {}: {}",
        text(instance),
        status_name(status),
        category,
        message
    );
    let mut kept = LOGGED.lock().unwrap_or_else(|p| p.into_inner());
    if kept.len() == LOG_KEPT {
        kept.remove(0);
    }
    // Its own words, shortened and on one line: they go into an error message.
    let line: String = format!("[{}] {category}: {message}", status_name(status))
        .chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .take(200)
        .collect();
    kept.push(line);
}

/// The FMU's last messages since [`take_log`]: a failing call's error
/// carries them, because the FMU's reason ("Wrong GUID.", a solver that
/// did not converge) is there and nowhere else.
static LOGGED: std::sync::Mutex<Vec<String>> = std::sync::Mutex::new(Vec::new());
const LOG_KEPT: usize = 4;

/// What the FMU logged since the last call, emptied.
pub fn take_log() -> Vec<String> {
    std::mem::take(&mut *LOGGED.lock().unwrap_or_else(|p| p.into_inner()))
}

#[repr(C)]
struct Callbacks {
    logger: unsafe extern "C" fn(*mut c_void, *const c_char, Status, *const c_char, *const c_char),
    allocate: unsafe extern "C" fn(usize, usize) -> *mut c_void,
    free: unsafe extern "C" fn(*mut c_void),
    step_finished: *const c_void,
    env: *mut c_void,
}

unsafe extern "C" fn allocate(n: usize, size: usize) -> *mut c_void {
    // SAFETY: calloc with any sizes is defined (null on failure).
    unsafe { libc::calloc(n, size) }
}

unsafe extern "C" fn free(p: *mut c_void) {
    // SAFETY: p came from allocate (calloc) or is null.
    unsafe { libc::free(p) }
}

/// The functions the import calls, by standard name.
pub const FUNCTIONS: [&str; 16] = [
    "fmi2GetVersion",
    "fmi2Instantiate",
    "fmi2FreeInstance",
    "fmi2SetupExperiment",
    "fmi2EnterInitializationMode",
    "fmi2ExitInitializationMode",
    "fmi2Terminate",
    "fmi2Reset",
    "fmi2SetReal",
    "fmi2SetInteger",
    "fmi2SetBoolean",
    "fmi2GetReal",
    "fmi2GetInteger",
    "fmi2GetBoolean",
    "fmi2DoStep",
    "fmi2SetDebugLogging",
];

struct Api {
    instantiate: unsafe extern "C" fn(
        *const c_char,
        c_int,
        *const c_char,
        *const c_char,
        *const Callbacks,
        c_int,
        c_int,
    ) -> Component,
    free_instance: unsafe extern "C" fn(Component),
    setup: unsafe extern "C" fn(Component, c_int, f64, f64, c_int, f64) -> Status,
    enter_init: unsafe extern "C" fn(Component) -> Status,
    exit_init: unsafe extern "C" fn(Component) -> Status,
    reset: unsafe extern "C" fn(Component) -> Status,
    set_real: unsafe extern "C" fn(Component, *const Vr, usize, *const f64) -> Status,
    set_integer: unsafe extern "C" fn(Component, *const Vr, usize, *const c_int) -> Status,
    set_boolean: unsafe extern "C" fn(Component, *const Vr, usize, *const c_int) -> Status,
    get_real: unsafe extern "C" fn(Component, *const Vr, usize, *mut f64) -> Status,
    get_integer: unsafe extern "C" fn(Component, *const Vr, usize, *mut c_int) -> Status,
    get_boolean: unsafe extern "C" fn(Component, *const Vr, usize, *mut c_int) -> Status,
    do_step: unsafe extern "C" fn(Component, f64, f64, c_int) -> Status,
}

fn dl_error() -> String {
    // SAFETY: dlerror returns null or a NUL-terminated string.
    let e = unsafe { libc::dlerror() };
    if e.is_null() {
        "unknown reason".into()
    } else {
        // SAFETY: non-null dlerror text.
        unsafe { CStr::from_ptr(e) }.to_string_lossy().into_owned()
    }
}

/// Opens `path` with `flags` (a library others must see, such as
/// libpython for a pythonfmu FMU, takes RTLD_GLOBAL).
pub fn open(path: &Path, global: bool) -> Result<*mut c_void, String> {
    let c = CString::new(path.as_os_str().to_string_lossy().as_bytes()).map_err(|_| "a NUL in the path")?;
    let flags = libc::RTLD_NOW | if global { libc::RTLD_GLOBAL } else { libc::RTLD_LOCAL };
    // SAFETY: dlopen of a path; the library's initialisers run here, in the worker.
    let h = unsafe { libc::dlopen(c.as_ptr(), flags) };
    if h.is_null() {
        Err(format!("cannot load {}: {}", path.display(), dl_error()))
    } else {
        Ok(h)
    }
}

/// A loaded FMU with one instance.
pub struct Instance {
    api: Api,
    comp: Component,
    callbacks: Box<Callbacks>,
}

/// A variable to read or write: value reference and type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Typed {
    Real(Vr),
    Integer(Vr),
    Boolean(Vr),
}

fn check(s: Status, call: &str) -> Result<(), String> {
    check_with(s, || call.to_string())
}

/// [`check`] with the call's description made only on failure (the
/// per-step calls would otherwise format a string each step).
fn check_with(s: Status, call: impl FnOnce() -> String) -> Result<(), String> {
    if s <= 1 {
        Ok(())
    } else {
        Err(format!("{} returned {}", call(), status_name(s)))
    }
}

impl Instance {
    /// Loads the library at `so`, resolves [`FUNCTIONS`] and instantiates
    /// a co-simulation instance with `guid` and the resources at `resources`.
    pub fn new(so: &Path, guid: &str, resources: &Path) -> Result<Self, String> {
        // A binary that does not load is most often one linked on a newer
        // Linux than this one (its glibc) or needing a library not here.
        let h = open(so, false).map_err(|e| {
            format!(
                "{e} (built on a newer Linux than this machine's, or needing a library it lacks? \
                 docs/your-model.md, \"Exporting your model\")"
            )
        })?;
        let sym = |name: &str| -> Result<*mut c_void, String> {
            let c = CString::new(name).map_err(|_| "a NUL in a name")?;
            // SAFETY: dlsym on a live handle.
            let p = unsafe { libc::dlsym(h, c.as_ptr()) };
            if p.is_null() {
                Err(format!("the FMU's binary has no function {name}"))
            } else {
                Ok(p)
            }
        };
        let mut at = Vec::with_capacity(FUNCTIONS.len());
        for f in FUNCTIONS {
            at.push(sym(f)?);
        }
        // SAFETY: each symbol is the standard's function of that name, whose
        // signature (FMI 2.0, section 2.1 and 4.2) is the pointer type given.
        let api = unsafe {
            use std::mem::transmute as t;
            Api {
                instantiate: t(at[1]),
                free_instance: t(at[2]),
                setup: t(at[3]),
                enter_init: t(at[4]),
                exit_init: t(at[5]),
                reset: t(at[7]),
                set_real: t(at[8]),
                set_integer: t(at[9]),
                set_boolean: t(at[10]),
                get_real: t(at[11]),
                get_integer: t(at[12]),
                get_boolean: t(at[13]),
                do_step: t(at[14]),
            }
        };
        let callbacks = Box::new(Callbacks {
            logger,
            allocate,
            free,
            step_finished: std::ptr::null(),
            env: std::ptr::null_mut(),
        });
        let uri = format!("file://{}", resources.display());
        let cstr = |s: &str| CString::new(s).map_err(|_| format!("a NUL in {s:?}"));
        let (name, guid_c, uri_c) = (cstr("hammer")?, cstr(guid)?, cstr(&uri)?);
        // SAFETY: the standard's call with live strings and callbacks (the
        // callbacks live as long as the instance: they are kept in it).
        let comp = unsafe { (api.instantiate)(name.as_ptr(), 1, guid_c.as_ptr(), uri_c.as_ptr(), &*callbacks, 0, 0) };
        if comp.is_null() {
            return Err("fmi2Instantiate returned no instance".into());
        }
        Ok(Self { api, comp, callbacks })
    }

    /// Sets the values before initialisation, runs to `stop_s` in steps of
    /// `step_s` and reads `outputs` at t = 0 and after each step, row by
    /// row, into `out` (cleared first; the worker keeps one buffer, so a
    /// run makes no allocation of its own). `reset` first when the
    /// instance ran before.
    /// `drive`, if given, is asked before each step for an input to set
    /// (held over the step) from the time and the last row read.
    #[allow(clippy::too_many_arguments)]
    pub fn run(
        &mut self,
        reset: bool,
        starts: &[(Typed, f64)],
        outputs: &[Typed],
        step_s: f64,
        steps: usize,
        mut drive: Option<&mut dyn FnMut(f64, &[f64]) -> (Typed, f64)>,
        out: &mut Vec<f64>,
    ) -> Result<(), String> {
        let c = self.comp;
        // SAFETY (every call below): the instance is live and the arrays
        // hold the counts passed.
        unsafe {
            if reset {
                check((self.api.reset)(c), "fmi2Reset")?;
            }
            let stop = step_s * steps as f64;
            check((self.api.setup)(c, 0, 0.0, 0.0, 1, stop), "fmi2SetupExperiment")?;
            for (v, x) in starts {
                self.set(*v, *x)?;
            }
            check((self.api.enter_init)(c), "fmi2EnterInitializationMode")?;
            check((self.api.exit_init)(c), "fmi2ExitInitializationMode")?;
        }
        let mut rows = Rows::of(outputs);
        out.clear();
        out.reserve(outputs.len() * (steps + 1));
        self.read(&mut rows, 0.0, out)?;
        for k in 0..steps {
            let t = step_s * k as f64;
            if let Some(d) = drive.as_mut() {
                let (input, value) = d(t, &out[out.len() - outputs.len()..]);
                if !value.is_finite() {
                    return Err(format!("the piston-force input at t = {t} s is {value}"));
                }
                // SAFETY: as above.
                unsafe { self.set(input, value)? };
            }
            // SAFETY: as above.
            let s = unsafe { (self.api.do_step)(c, t, step_s, 1) };
            check_with(s, || format!("fmi2DoStep at t = {t} s"))?;
            self.read(&mut rows, step_s * (k + 1) as f64, out)?;
        }
        Ok(())
    }

    unsafe fn set(&mut self, v: Typed, x: f64) -> Result<(), String> {
        let c = self.comp;
        // SAFETY: one value, live instance.
        let s = unsafe {
            match v {
                Typed::Real(vr) => (self.api.set_real)(c, &vr, 1, &x),
                Typed::Integer(vr) => (self.api.set_integer)(c, &vr, 1, &(x.round() as c_int)),
                Typed::Boolean(vr) => (self.api.set_boolean)(c, &vr, 1, &c_int::from(x != 0.0)),
            }
        };
        check_with(s, || format!("setting value reference {} to {x}", vr_of(v)))
    }

    /// One row: each base type's outputs in one `fmi2Get*` call (a call
    /// per value cost a third of a run of the project's own FMU), then
    /// placed in the row's order and checked finite.
    fn read(&mut self, rows: &mut Rows, t: f64, out: &mut Vec<f64>) -> Result<(), String> {
        let c = self.comp;
        let n = (rows.real_vr.len(), rows.int_vr.len(), rows.bool_vr.len());
        // SAFETY: each array holds the count passed; live instance.
        let s = unsafe {
            let mut s = 0;
            if n.0 > 0 {
                s = s.max((self.api.get_real)(
                    c,
                    rows.real_vr.as_ptr(),
                    n.0,
                    rows.reals.as_mut_ptr(),
                ));
            }
            if n.1 > 0 {
                s = s.max((self.api.get_integer)(
                    c,
                    rows.int_vr.as_ptr(),
                    n.1,
                    rows.ints.as_mut_ptr(),
                ));
            }
            if n.2 > 0 {
                s = s.max((self.api.get_boolean)(
                    c,
                    rows.bool_vr.as_ptr(),
                    n.2,
                    rows.bools.as_mut_ptr(),
                ));
            }
            s
        };
        if s > 1 {
            // Which value failed: asked one by one, as the message names it.
            return Err(self
                .read_singly(&rows.outputs, t)
                .err()
                .unwrap_or_else(|| format!("reading the outputs at t = {t} s returned {}", status_name(s))));
        }
        for (j, &(group, k)) in rows.order.iter().enumerate() {
            let x = match group {
                Group::Real => rows.reals[k],
                Group::Integer => f64::from(rows.ints[k]),
                Group::Boolean => f64::from(rows.bools[k]),
            };
            if !x.is_finite() {
                return Err(format!(
                    "non-finite output (value reference {}) = {x} at t = {t} s",
                    vr_of(rows.outputs[j])
                ));
            }
            out.push(x);
        }
        Ok(())
    }

    /// The outputs read one call each: the failing one named.
    fn read_singly(&mut self, outputs: &[Typed], t: f64) -> Result<(), String> {
        for v in outputs {
            let mut r = 0.0f64;
            let mut i: c_int = 0;
            // SAFETY: one value, live instance.
            let s = unsafe {
                match *v {
                    Typed::Real(vr) => (self.api.get_real)(self.comp, &vr, 1, &mut r),
                    Typed::Integer(vr) => (self.api.get_integer)(self.comp, &vr, 1, &mut i),
                    Typed::Boolean(vr) => (self.api.get_boolean)(self.comp, &vr, 1, &mut i),
                }
            };
            check_with(s, || format!("reading value reference {} at t = {t} s", vr_of(*v)))?;
        }
        Ok(())
    }
}

#[derive(Clone, Copy)]
enum Group {
    Real,
    Integer,
    Boolean,
}

/// The outputs of a row grouped by base type, and where each goes.
struct Rows {
    outputs: Vec<Typed>,
    real_vr: Vec<Vr>,
    int_vr: Vec<Vr>,
    bool_vr: Vec<Vr>,
    reals: Vec<f64>,
    ints: Vec<c_int>,
    bools: Vec<c_int>,
    /// Per column of the row: which group, and the place in it.
    order: Vec<(Group, usize)>,
}

impl Rows {
    fn of(outputs: &[Typed]) -> Self {
        let mut r = Rows {
            outputs: outputs.to_vec(),
            real_vr: Vec::new(),
            int_vr: Vec::new(),
            bool_vr: Vec::new(),
            reals: Vec::new(),
            ints: Vec::new(),
            bools: Vec::new(),
            order: Vec::new(),
        };
        for v in outputs {
            let (kind, group, vr) = match *v {
                Typed::Real(vr) => (Group::Real, &mut r.real_vr, vr),
                Typed::Integer(vr) => (Group::Integer, &mut r.int_vr, vr),
                Typed::Boolean(vr) => (Group::Boolean, &mut r.bool_vr, vr),
            };
            group.push(vr);
            r.order.push((kind, group.len() - 1));
        }
        r.reals = vec![0.0; r.real_vr.len()];
        r.ints = vec![0; r.int_vr.len()];
        r.bools = vec![0; r.bool_vr.len()];
        r
    }
}

fn vr_of(v: Typed) -> Vr {
    match v {
        Typed::Real(r) | Typed::Integer(r) | Typed::Boolean(r) => r,
    }
}

impl Drop for Instance {
    fn drop(&mut self) {
        // SAFETY: the instance is live; freed once. The callbacks outlive it.
        unsafe { (self.api.free_instance)(self.comp) };
        let _ = &self.callbacks;
    }
}
