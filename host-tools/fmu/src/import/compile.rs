//! A source-code FMU compiled for this platform: the C (or C++) files its
//! description lists, built with the system's compiler into
//! `binaries/linux64/<modelIdentifier>.so`, written out as a new FMU beside
//! the sources. Tools export sources where their binary is for another
//! platform (a Windows workstation's FMU read on a Linux bench PC):
//! OpenModelica by default, the Modelica Association's Reference FMUs,
//! Simulink and Dymola with the option.
//!
//! Explicit (`hammer fmu compile`), never on load: the engineer sees the
//! compiler's errors once, and the diagnosis runs the binary they checked.
//! What is built comes from `sources/buildDescription.xml` when the FMU has
//! one (its preprocessor definitions and include directories), else from
//! the co-simulation interface's `SourceFiles`. The binary exports the
//! standard function names, whatever prefix the sources give them.

use std::path::{Path, PathBuf};
use std::process::Command;

use super::archive::{entries, unpack};
use super::describe::{Build, Description};
use super::{FailKind, FmuError};

/// What [`compile`] built.
#[derive(Debug, Clone)]
pub struct Compiled {
    /// The FMU written: the original's files and the new binary.
    pub out: PathBuf,
    /// Its entry, `binaries/linux64/<id>.so`.
    pub binary: String,
    /// The files compiled, relative to `sources/`.
    pub sources: Vec<String>,
    /// The compiler driver that linked it (`$CC`, `cc`, or `$CXX`, `c++`
    /// when a source is C++).
    pub linker: String,
}

/// Lines of the compiler's errors an error message carries.
const ERROR_LINES: usize = 6;

/// Compiles the sources of `fmu` and writes `out`: every entry of `fmu`,
/// its linux64 binary (if any) replaced by the one built here.
pub fn compile(fmu: &Path, out: &Path) -> Result<Compiled, FmuError> {
    let fail = |kind, detail: String| FmuError {
        fmu: fmu.to_path_buf(),
        kind,
        detail,
    };
    let bytes = std::fs::read(fmu).map_err(|e| fail(FailKind::Open, format!("cannot read it: {e}")))?;
    let files = entries(&bytes).map_err(|e| fail(FailKind::NotZip, e))?;
    let unpacked = unpack(fmu).map_err(|e| fail(FailKind::NotZip, e))?;
    let (desc, id) = Description::read_cosim(&unpacked.dir).map_err(|e| fail(FailKind::Description, e))?;
    let sources_dir = unpacked.dir.join("sources");
    let build = match std::fs::read_to_string(sources_dir.join("buildDescription.xml")) {
        Ok(text) => Build::parse(&text, &id)
            .map_err(|e| fail(FailKind::Description, format!("sources/buildDescription.xml: {e}")))?
            .ok_or_else(|| {
                fail(
                    FailKind::Description,
                    format!("sources/buildDescription.xml has no build configuration for {id}"),
                )
            })?,
        Err(_) => Build {
            sources: desc.source_files.clone(),
            ..Build::default()
        },
    };
    if build.sources.is_empty() {
        return Err(fail(
            FailKind::NoBinary,
            "no sources to compile: its description lists no source files (a binary-only FMU)".into(),
        ));
    }
    for s in &build.sources {
        let rel = Path::new(s);
        if rel.components().any(|c| !matches!(c, std::path::Component::Normal(_))) || !sources_dir.join(rel).is_file() {
            return Err(fail(
                FailKind::NoBinary,
                format!("source file {s} is listed but not in sources/"),
            ));
        }
    }
    let is_cxx = |s: &str| [".cpp", ".cc", ".cxx", ".C"].iter().any(|e| s.ends_with(e));
    let cxx = build.sources.iter().any(|s| is_cxx(s));
    let driver = |var: &str, default: &str| std::env::var(var).unwrap_or_else(|_| default.to_string());
    let (cc, cxx_driver) = (driver("CC", "cc"), driver("CXX", "c++"));
    let objects = unpacked.dir.join("objects");
    std::fs::create_dir_all(&objects).map_err(|e| fail(FailKind::NoBinary, format!("{}: {e}", objects.display())))?;
    let mut flags: Vec<String> = vec!["-fPIC".into(), "-O2".into(), "-fvisibility=default".into()];
    flags.push(format!("-I{}", sources_dir.display()));
    for inc in &build.include_dirs {
        flags.push(format!("-I{}", sources_dir.join(inc).display()));
    }
    for (name, value) in &build.definitions {
        flags.push(match value {
            Some(v) => format!("-D{name}={v}"),
            None => format!("-D{name}"),
        });
    }
    let mut objs = Vec::new();
    for (i, s) in build.sources.iter().enumerate() {
        let obj = objects.join(format!("{i}.o"));
        let mut cmd = Command::new(if is_cxx(s) { &cxx_driver } else { &cc });
        cmd.current_dir(&sources_dir)
            .args(&flags)
            .arg("-c")
            .arg(sources_dir.join(s))
            .arg("-o")
            .arg(&obj);
        run(cmd, &format!("compiling {s}"), &unpacked.dir).map_err(|e| fail(FailKind::Compile, e))?;
        objs.push(obj);
    }
    let linker = if cxx { cxx_driver } else { cc };
    let binary = format!("binaries/linux64/{id}.so");
    let so = unpacked.dir.join("built.so");
    let link = |aliases: &[String]| {
        let mut cmd = Command::new(&linker);
        cmd.arg("-shared")
            .args(&objs)
            .arg("-o")
            .arg(&so)
            .args(["-lm", "-ldl", "-lpthread"]);
        cmd.args(aliases.iter().map(|a| format!("-Wl,--defsym={a}")));
        run(cmd, "linking", &unpacked.dir).map_err(|e| fail(FailKind::Compile, e))
    };
    link(&[])?;
    // Source FMUs name their functions with the model identifier as a
    // prefix (FMI 2.0, 2.1.1: `FMI2_FUNCTION_PREFIX`, for static linking);
    // a binary FMU must export the standard names. Linked again with each
    // prefixed function also under its standard name, the binary is one
    // any importer (FMPy, this one) loads.
    let exported = exported(&so).map_err(|e| fail(FailKind::Compile, e))?;
    if !exported.iter().any(|s| s == "fmi2Instantiate") {
        let prefix = format!("{id}_");
        let aliases: Vec<String> = exported
            .iter()
            .filter_map(|s| {
                s.strip_prefix(&prefix)
                    .filter(|f| f.starts_with("fmi2"))
                    .map(|f| format!("{f}={s}"))
            })
            .collect();
        link(&aliases)?;
        if !exported_by(&so, "fmi2Instantiate") {
            return Err(fail(
                FailKind::Compile,
                format!("the binary built exports no fmi2Instantiate (nor {prefix}fmi2Instantiate): are these the sources of an FMI 2.0 FMU?"),
            ));
        }
    }
    let built = std::fs::read(&so).map_err(|e| fail(FailKind::NoBinary, format!("the binary built: {e}")))?;
    let mut written: Vec<(String, Vec<u8>)> = files.into_iter().filter(|(n, _)| *n != binary).collect();
    written.push((binary.clone(), built));
    std::fs::write(out, crate::package::zip_stored(&written)).map_err(|e| FmuError {
        fmu: out.to_path_buf(),
        kind: FailKind::Open,
        detail: format!("cannot write it: {e}"),
    })?;
    Ok(Compiled {
        out: out.to_path_buf(),
        binary,
        sources: build.sources,
        linker,
    })
}

/// The functions a shared library exports (its defined dynamic symbols).
fn exported(so: &Path) -> Result<Vec<String>, String> {
    use object::{Object, ObjectSymbol};
    let data = std::fs::read(so).map_err(|e| format!("the binary built: {e}"))?;
    let file = object::File::parse(&*data).map_err(|e| format!("the binary built is not a shared library: {e}"))?;
    Ok(file
        .dynamic_symbols()
        .filter(|s| s.is_definition())
        .filter_map(|s| s.name().ok().map(String::from))
        .collect())
}

fn exported_by(so: &Path, name: &str) -> bool {
    exported(so).is_ok_and(|e| e.iter().any(|s| s == name))
}

/// Runs one compiler step; on failure its first error lines (the
/// compiler's own words about the FMU's sources), paths relative to the
/// FMU (`sources/all.c:3:1: error: …`), not to where it was unpacked.
fn run(mut cmd: Command, what: &str, unpacked: &Path) -> Result<(), String> {
    let program = cmd.get_program().to_string_lossy().into_owned();
    let out = cmd
        .output()
        .map_err(|e| format!("{what}: cannot run the compiler {program}: {e} (install a C compiler, or set CC)"))?;
    if out.status.success() {
        return Ok(());
    }
    let stderr = String::from_utf8_lossy(&out.stderr).replace(&format!("{}/", unpacked.display()), "");
    let errors: Vec<&str> = stderr.lines().filter(|l| l.contains("error")).collect();
    let pick = if errors.is_empty() {
        stderr.lines().collect()
    } else {
        errors
    };
    let lines: Vec<String> = pick
        .into_iter()
        .take(ERROR_LINES)
        .map(|l| l.chars().take(200).collect())
        .collect();
    Err(format!(
        "{what}: {program} failed ({}): {}",
        out.status,
        if lines.is_empty() {
            "no message".to_string()
        } else {
            lines.join(" | ")
        }
    ))
}
