//! The hammer's reference record: what `hammer commission` writes into its
//! folder (`commission.json` beside one trace per captured cycle), read by
//! the diagnosis' inputs ([`crate::input::read_request`]: `hammer diagnose
//! --reference`, the Python package) and by the monitor's drift since
//! commissioning (`monitor` and `demo --reference`).
//!
//! A commissioning folder is data people copy between machines, so every
//! command reads it through one reader, [`Folder::open`], which trusts
//! nothing the record names: a capture is a relative path inside the folder
//! once symbolic links are resolved (a record naming `/etc/shadow`, a
//! `..` path or a link out of the folder would have another file read and
//! its first line quoted in the error), a regular file (a FIFO would hang
//! the reader that opens it), listed once (two points sharing captures mix
//! them silently), and its sidecar states the point's supply pressure and
//! the record's calibration (a relabelled pressure gives a wrong number,
//! not an error). A refused file is named, never opened.

use std::collections::HashMap;
use std::path::{Component, Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use hammer_trace::trace::{read_sidecar, sidecar_path};
use serde::{Deserialize, Serialize};

/// The record's file in a commissioning folder.
pub const RECORD_FILE: &str = "commission.json";
pub const RECORD_FORMAT: &str = "hammer-commission";
/// Version 2 adds each point's `reports` (the board's own reports of the
/// point's cycles); a version-1 record has captures alone and still reads.
pub const RECORD_VERSION: u32 = 2;

/// How far a point's supply pressure and its captures' sidecars may differ,
/// bar: `hammer commission` writes the same number into both, and takes a
/// pressure within this of a recorded point for that point (it replaces it).
pub const SUPPLY_AGREE_BAR: f64 = 0.005;

/// The highest supply pressure a record may hold, gauge bar: the model's
/// (a record is read against it and diagnosed with it).
const SUPPLY_MAX_BAR: f64 = hammer_sim::params::SUPPLY_BAR_RANGE.1;

/// What `commission.json` holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Record {
    pub format: String,
    pub version: u32,
    /// `major.minor.patch` as the board reports it.
    pub firmware_version: String,
    pub board: String,
    /// CRC-32 of the channel calibrations the captures were read with.
    pub calibration_hash: u32,
    pub points: Vec<PointRecord>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PointRecord {
    pub supply_bar: f64,
    /// Trace files, relative to the folder.
    pub traces: Vec<String>,
    /// The board's reports of the point's cycles while it was captured
    /// (`reports.csv`, the columns of `hammer estimate --format csv`),
    /// relative to the folder: the characteristics as the board reads
    /// them, which the drift is read against. Absent in a version-1 record.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reports: Option<String>,
}

impl Record {
    /// The record from its text (`label` names it in errors), with what can
    /// be checked without the folder: its format, at least one operating
    /// point, each with a supply pressure and captures, every capture a
    /// relative path without `..` listed once.
    pub fn parse(text: &str, label: &str) -> Result<Record> {
        let r: Record = serde_json::from_str(text)
            .map_err(|e| anyhow!("{label}: not a commissioning record ({})", json_error(&e)))?;
        if r.format != RECORD_FORMAT {
            bail!("{label}: not a commissioning record (its `format` is not `{RECORD_FORMAT}`)");
        }
        if r.version > RECORD_VERSION {
            bail!(
                "{label}: version {} of {RECORD_FORMAT}, this tool reads up to version {RECORD_VERSION}",
                r.version
            );
        }
        if r.points.is_empty() {
            bail!("{label}: the record holds no operating point (`points` is empty): nothing to read against; commission the hammer again");
        }
        let mut listed: HashMap<PathBuf, f64> = HashMap::new();
        for p in &r.points {
            let bar = p.supply_bar;
            if !(bar.is_finite() && bar > 0.0 && bar <= SUPPLY_MAX_BAR) {
                bail!("{label}: a point's supply pressure {bar} bar is not a gauge pressure between 0 and {SUPPLY_MAX_BAR} bar");
            }
            if p.traces.is_empty() {
                bail!("{label}: the point at {bar} bar lists no capture");
            }
            for t in p.traces.iter().chain(&p.reports) {
                let rel = relative(t).map_err(|why| {
                    anyhow!("{label}: the file {t:?} at {bar} bar {why}: a record's captures and reports are paths inside its folder")
                })?;
                if let Some(other) = listed.insert(rel, bar) {
                    bail!("{label}: the file {t:?} is listed twice (at {other} bar and at {bar} bar): each capture and report file belongs to one point");
                }
            }
        }
        Ok(r)
    }
}

/// A commissioning folder whose record was read and checked against its
/// captures: the only way to them ([`Folder::traces`]).
#[derive(Debug, Clone)]
pub struct Folder {
    pub dir: PathBuf,
    pub record: Record,
    pub points: Vec<Point>,
}

/// An operating point's captures, each `dir` joined with its checked path.
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    pub supply_bar: f64,
    pub traces: Vec<PathBuf>,
    /// The board's reports of the point, checked as a capture is.
    pub reports: Option<PathBuf>,
}

impl Folder {
    /// Reads and checks the record of `dir` (see the module's doc): every
    /// capture and sidecar is checked before any is opened.
    pub fn open(dir: &Path) -> Result<Folder> {
        let root = dir
            .canonicalize()
            .with_context(|| format!("{}: not a commissioning folder", dir.display()))?;
        let path = dir.join(RECORD_FILE);
        confined(&root, &path).with_context(|| format!("{}: not a commissioning folder", dir.display()))?;
        let label = path.display().to_string();
        let text = std::fs::read_to_string(&path).with_context(|| format!("reading {label}"))?;
        let record = Record::parse(&text, &label)?;
        Folder::of(dir, record, &label)
    }

    /// `record`'s captures in `dir`, checked as [`Folder::open`] checks
    /// them (`label` names the record in errors).
    pub fn of(dir: &Path, record: Record, label: &str) -> Result<Folder> {
        let root = dir
            .canonicalize()
            .with_context(|| format!("{}: not a commissioning folder", dir.display()))?;
        let mut files: HashMap<PathBuf, f64> = HashMap::new();
        let mut points = Vec::new();
        for p in &record.points {
            // Each file the point lists, checked; `kind` names it in errors.
            let mut checked = |t: &String, kind: &str| -> Result<PathBuf> {
                let what = || format!("{label}: the {kind} {t:?} at {} bar", p.supply_bar);
                // (Checked by `parse`.)
                let rel = relative(t).map_err(|why| anyhow!("{label}: {t:?} {why}"))?;
                let file = dir.join(&rel);
                let real = confined(&root, &file).with_context(what)?;
                if let Some(other) = files.insert(real.clone(), p.supply_bar) {
                    bail!(
                        "{label}: the {kind} {t:?} at {} bar is the same file as one at {other} bar: each capture and report file belongs to one point",
                        p.supply_bar
                    );
                }
                agrees(&root, &record, p, &file).with_context(what)?;
                // A link inside the folder: the file it names has its own sidecar.
                if real != root.join(&rel) {
                    agrees(&root, &record, p, &real).with_context(what)?;
                }
                Ok(file)
            };
            let traces = p.traces.iter().map(|t| checked(t, "capture")).collect::<Result<_>>()?;
            let reports = p.reports.as_ref().map(|r| checked(r, "reports")).transpose()?;
            points.push(Point {
                supply_bar: p.supply_bar,
                traces,
                reports,
            });
        }
        Ok(Folder {
            dir: dir.to_path_buf(),
            record,
            points,
        })
    }

    /// Every capture with its point's supply pressure.
    pub fn traces(&self) -> impl Iterator<Item = (&Path, f64)> + '_ {
        self.points
            .iter()
            .flat_map(|p| p.traces.iter().map(|t| (t.as_path(), p.supply_bar)))
    }
}

/// Whether `path` is a commissioning folder: a folder with a record (which
/// [`Folder::open`] then checks; a record that is a FIFO or a link out is
/// refused there, not taken for a trace).
pub fn is_record(path: &Path) -> bool {
    path.is_dir() && path.join(RECORD_FILE).symlink_metadata().is_ok()
}

/// A capture's path as the record gives it, made relative and plain, or
/// why it is not one.
fn relative(t: &str) -> Result<PathBuf, &'static str> {
    if t.contains('\0') {
        return Err("holds a NUL character");
    }
    let mut out = PathBuf::new();
    for c in Path::new(t).components() {
        match c {
            Component::Normal(s) => out.push(s),
            Component::CurDir => {}
            Component::ParentDir => return Err("climbs out with `..`"),
            Component::RootDir | Component::Prefix(_) => return Err("is an absolute path"),
        }
    }
    if out.as_os_str().is_empty() {
        return Err("names no file");
    }
    Ok(out)
}

/// Where `path` really is, when that is a regular file inside `root` (the
/// folder, resolved): else why not, naming it. Checked on the file's
/// metadata, never by opening it.
fn confined(root: &Path, path: &Path) -> Result<PathBuf> {
    let real = path.canonicalize().with_context(|| format!("{}", path.display()))?;
    if !real.starts_with(root) {
        bail!(
            "{} leads outside the commissioning folder {} (a symbolic link out of it): refused, not read",
            path.display(),
            root.display()
        );
    }
    let meta = std::fs::metadata(&real).with_context(|| format!("{}", path.display()))?;
    if !meta.is_file() {
        bail!(
            "{} is not a regular file (a FIFO, a device or a folder): refused, not read",
            path.display()
        );
    }
    Ok(real)
}

/// Whether the sidecar of a capture (`trace`) of point `p` agrees with the
/// point and the record: the supply pressure within [`SUPPLY_AGREE_BAR`],
/// the calibration hash equal, where the sidecar states them. A capture
/// without a sidecar has the record's pressure.
fn agrees(root: &Path, record: &Record, p: &PointRecord, trace: &Path) -> Result<()> {
    let side = sidecar_path(trace);
    if side.symlink_metadata().is_err() {
        return Ok(());
    }
    confined(root, &side).context("its sidecar")?;
    let Some(s) = read_sidecar(trace)? else {
        return Ok(());
    };
    if let Some(bar) = s.supply_pressure_bar {
        if !((bar - p.supply_bar).abs() <= SUPPLY_AGREE_BAR) {
            bail!(
                "the record says {} bar, its sidecar {} says {bar} bar (they must agree within {SUPPLY_AGREE_BAR} bar): a relabelled record reads wrong numbers, so it is refused",
                p.supply_bar,
                side.display()
            );
        }
    }
    if let Some(h) = s.calibration_hash {
        if h != record.calibration_hash {
            bail!(
                "the record says calibration {:08x}, its sidecar {} says {h:08x}: captures of another calibration are not this record's",
                record.calibration_hash,
                side.display()
            );
        }
    }
    Ok(())
}

/// Why a text is not a record, by where and what kind, without serde's
/// message (which quotes the text's values).
fn json_error(e: &serde_json::Error) -> String {
    use serde_json::error::Category;
    let what = match e.classify() {
        Category::Io => "unreadable",
        Category::Syntax => "not JSON",
        Category::Eof => "JSON cut short",
        Category::Data => "JSON without the record's fields and types",
    };
    format!("{what} at line {} column {}", e.line(), e.column())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn text(points: &str) -> String {
        format!(
            r#"{{"format":"hammer-commission","version":1,"firmware_version":"0.1.0","board":"b","calibration_hash":1,"points":{points}}}"#
        )
    }

    /// The record's own checks, before any file is looked at.
    #[test]
    fn a_record_names_relative_paths_inside_its_folder_once() {
        let ok = Record::parse(
            &text(r#"[{"supply_bar":4,"traces":["4.0bar/a.csv","./4.0bar/b.csv"]}]"#),
            "r",
        )
        .unwrap();
        assert_eq!(ok.points[0].traces.len(), 2);
        // Version 1 has no reports; version 2 names them.
        assert_eq!(ok.points[0].reports, None);
        let v2 = text(r#"[{"supply_bar":4,"traces":["a.csv"],"reports":"4.0bar/reports.csv"}]"#)
            .replace("\"version\":1", "\"version\":2");
        let v2 = Record::parse(&v2, "r").unwrap();
        assert_eq!(v2.points[0].reports.as_deref(), Some("4.0bar/reports.csv"));
        for (points, why) in [
            ("[]", "no operating point"),
            (r#"[{"supply_bar":4,"traces":["../../../../etc/shadow"]}]"#, "`..`"),
            (r#"[{"supply_bar":4,"traces":["/etc/passwd"]}]"#, "absolute"),
            (r#"[{"supply_bar":4,"traces":["."]}]"#, "names no file"),
            (r#"[{"supply_bar":4,"traces":[]}]"#, "lists no capture"),
            (r#"[{"supply_bar":-4,"traces":["a.csv"]}]"#, "gauge pressure"),
            (
                r#"[{"supply_bar":4,"traces":["4.0bar/a.csv"]},{"supply_bar":4.04,"traces":["4.0bar//a.csv"]}]"#,
                "listed twice",
            ),
            // A point's reports are a file of the folder like its captures.
            (
                r#"[{"supply_bar":4,"traces":["a.csv"],"reports":"../reports.csv"}]"#,
                "`..`",
            ),
            (
                r#"[{"supply_bar":4,"traces":["a.csv"],"reports":"./a.csv"}]"#,
                "listed twice",
            ),
        ] {
            let e = Record::parse(&text(points), "r").unwrap_err().to_string();
            assert!(e.starts_with("r: ") && e.contains(why), "{points}: {e}");
        }
        // serde's message would quote the value; ours says where.
        let e = Record::parse(r#"{"format": "root:x:0:0"}"#, "r")
            .unwrap_err()
            .to_string();
        assert!(!e.contains("root") && e.contains("line 1"), "{e}");
        let e = Record::parse(&text("[]").replace("hammer-commission", "secret"), "r")
            .unwrap_err()
            .to_string();
        assert!(!e.contains("secret"), "{e}");
    }
}
