//! A QEMU TCG plugin (QEMU's plugin API version 1, QEMU 7.2): counts the
//! instructions the guest executes in each function, for the firmware
//! bench's per-function split (`cargo xtask bench-firmware`).
//!
//! Each translation block gets an inline counter that adds the block's
//! instruction count every time it runs (no callback into the plugin, so the
//! guest runs at nearly full speed); the block is named by QEMU's own
//! symbol lookup in the `-kernel` ELF. At QEMU's exit the counts, summed per
//! symbol, go to the file named by the `out=` argument, one
//! `instructions<TAB>symbol` line each (mangled; `?` for code no symbol
//! covers). Under `-icount` the counts are the guest's: they do not depend
//! on the host.
//!
//! `qemu-system-arm … -plugin target/release/libqemu_profile.so,out=FILE`.
//! The functions below are QEMU's, resolved from its executable when it
//! loads the plugin.

use std::collections::BTreeMap;
use std::ffi::{c_char, c_int, c_void, CStr};
use std::sync::Mutex;

type PluginId = u64;
#[repr(C)]
struct Tb {
    _opaque: [u8; 0],
}
#[repr(C)]
struct Insn {
    _opaque: [u8; 0],
}
/// `enum qemu_plugin_op`: `QEMU_PLUGIN_INLINE_ADD_U64`.
const INLINE_ADD_U64: c_int = 0;

extern "C" {
    fn qemu_plugin_register_vcpu_tb_trans_cb(id: PluginId, cb: extern "C" fn(PluginId, *mut Tb));
    fn qemu_plugin_register_vcpu_tb_exec_inline(tb: *mut Tb, op: c_int, ptr: *mut c_void, imm: u64);
    fn qemu_plugin_register_atexit_cb(id: PluginId, cb: extern "C" fn(PluginId, *mut c_void), userdata: *mut c_void);
    fn qemu_plugin_tb_n_insns(tb: *const Tb) -> usize;
    fn qemu_plugin_tb_get_insn(tb: *const Tb, idx: usize) -> *mut Insn;
    fn qemu_plugin_insn_symbol(insn: *const Insn) -> *const c_char;
    fn qemu_plugin_outs(s: *const c_char);
}

/// The plugin API version this plugin is written against (QEMU checks it).
#[no_mangle]
pub static qemu_plugin_version: c_int = 1;

/// One translated block's counter: where QEMU adds, and whose it is.
struct Counter {
    /// Instructions executed; QEMU's generated code adds to it in place.
    /// Allocated once and never freed, so the address stays valid for QEMU.
    count: *mut u64,
    symbol: String,
}

struct State {
    out: String,
    counters: Vec<Counter>,
}

// SAFETY: the counters are only read once the vCPU has stopped (at exit).
unsafe impl Send for State {}

static STATE: Mutex<Option<State>> = Mutex::new(None);

/// The symbol QEMU finds for a block: that of its last instruction (an
/// ARM Thumb function's symbol is its address + 1, so a lookup at a
/// function's first instruction can miss it; a block never spans two
/// functions), else of any other of its instructions.
fn symbol_of(tb: *mut Tb) -> String {
    // SAFETY: `tb` is the block QEMU is translating, valid during the callback.
    let n = unsafe { qemu_plugin_tb_n_insns(tb) };
    for i in (0..n).rev() {
        // SAFETY: i < n; QEMU returns a valid instruction handle and a
        // NUL-terminated name it owns, or null.
        let name = unsafe { qemu_plugin_insn_symbol(qemu_plugin_tb_get_insn(tb, i)) };
        if !name.is_null() {
            // SAFETY: see above.
            return unsafe { CStr::from_ptr(name) }.to_string_lossy().into_owned();
        }
    }
    "?".into()
}

extern "C" fn on_translate(_id: PluginId, tb: *mut Tb) {
    // SAFETY: valid during the callback.
    let n = unsafe { qemu_plugin_tb_n_insns(tb) } as u64;
    let symbol = symbol_of(tb);
    let count = Box::into_raw(Box::new(0u64));
    // SAFETY: the counter lives for the rest of the process; QEMU's code
    // adds to it on the vCPU thread.
    unsafe { qemu_plugin_register_vcpu_tb_exec_inline(tb, INLINE_ADD_U64, count.cast(), n) };
    if let Ok(mut state) = STATE.lock() {
        if let Some(s) = state.as_mut() {
            s.counters.push(Counter { count, symbol });
        }
    }
}

fn say(text: &str) {
    if let Ok(c) = std::ffi::CString::new(text) {
        // SAFETY: a NUL-terminated string QEMU only reads.
        unsafe { qemu_plugin_outs(c.as_ptr()) };
    }
}

extern "C" fn on_exit(_id: PluginId, _data: *mut c_void) {
    let Ok(state) = STATE.lock() else { return };
    let Some(s) = state.as_ref() else { return };
    let mut per_symbol: BTreeMap<&str, u64> = BTreeMap::new();
    for c in &s.counters {
        // SAFETY: allocated in `on_translate`, never freed; the vCPU has
        // stopped, so QEMU no longer writes it.
        let n = unsafe { std::ptr::read_volatile(c.count) };
        *per_symbol.entry(&c.symbol).or_default() += n;
    }
    let text: String = per_symbol
        .iter()
        .filter(|(_, &n)| n > 0)
        .map(|(sym, n)| format!("{n}\t{sym}\n"))
        .collect();
    if let Err(e) = std::fs::write(&s.out, text) {
        say(&format!("qemu-profile: cannot write {}: {e}\n", s.out));
    }
}

/// QEMU calls this when it loads the plugin: `out=FILE` is required.
///
/// # Safety
/// QEMU passes `argc` valid NUL-terminated strings in `argv`.
#[no_mangle]
pub unsafe extern "C" fn qemu_plugin_install(
    id: PluginId,
    _info: *const c_void,
    argc: c_int,
    argv: *const *const c_char,
) -> c_int {
    let mut out = None;
    for i in 0..usize::try_from(argc).unwrap_or(0) {
        // SAFETY: the caller's contract.
        let arg = unsafe { CStr::from_ptr(*argv.add(i)) }.to_string_lossy();
        if let Some(path) = arg.strip_prefix("out=") {
            out = Some(path.to_string());
        }
    }
    let Some(out) = out else {
        say("qemu-profile: give the output file as out=FILE\n");
        return -1;
    };
    let Ok(mut state) = STATE.lock() else { return -1 };
    *state = Some(State {
        out,
        counters: Vec::new(),
    });
    drop(state);
    // SAFETY: QEMU's registration calls, with callbacks of the declared types.
    unsafe {
        qemu_plugin_register_vcpu_tb_trans_cb(id, on_translate);
        qemu_plugin_register_atexit_cb(id, on_exit, std::ptr::null_mut());
    }
    0
}
