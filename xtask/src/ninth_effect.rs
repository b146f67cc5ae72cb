//! `cargo xtask ninth-effect`: the registry's promise, tested. A copy of the
//! workspace gets the test effect of `xtask/fixtures/ninth-effect` the way
//! docs/model.md's recipe says (its simulator file, its diagnosis file, one
//! `catalogue!` line, one docs row) and nothing else; then the simulator's
//! registry tests and the fixture's own test run there.

use std::path::{Path, PathBuf};
use std::process::Command;

const NAME: &str = "quadratic_drag";
const TYPE: &str = "QuadraticDrag";

fn write(path: &Path, text: &str) -> Result<(), String> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    std::fs::write(path, text).map_err(|e| format!("{}: {e}", path.display()))
}

fn read(path: &Path) -> Result<String, String> {
    std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))
}

/// The workspace's files copied to `to`: git's list (tracked and new, not
/// ignored) in a git checkout, else every file outside build output. The
/// firmware (not a member) and the fuzz crate (taken out of the copy's
/// members in [`run`]) stay out: the registry reaches neither.
fn copy_workspace(root: &Path, to: &Path) -> Result<(), String> {
    let files = git_files(root).unwrap_or_else(|| {
        let mut out = Vec::new();
        walk(root, root, &mut out);
        out
    });
    if to.exists() {
        std::fs::remove_dir_all(to).map_err(|e| format!("{}: {e}", to.display()))?;
    }
    for rel in files {
        if rel.starts_with("firmware/") || rel.starts_with("fuzz/") {
            continue;
        }
        let (src, dst) = (root.join(&rel), to.join(&rel));
        if !src.is_file() {
            continue; // deleted in the work tree
        }
        if let Some(dir) = dst.parent() {
            std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        }
        std::fs::copy(&src, &dst).map_err(|e| format!("{}: {e}", src.display()))?;
    }
    Ok(())
}

fn git_files(root: &Path) -> Option<Vec<String>> {
    let out = Command::new("git")
        .args(["ls-files", "-co", "--exclude-standard", "-z"])
        .current_dir(root)
        .output()
        .ok()
        .filter(|o| o.status.success())?;
    let files: Vec<String> = out
        .stdout
        .split(|b| *b == 0)
        .filter(|f| !f.is_empty())
        .map(|f| String::from_utf8_lossy(f).into_owned())
        .collect();
    (!files.is_empty()).then_some(files)
}

/// Every file under `dir` (relative to `root`), build output and VCS data left out.
fn walk(root: &Path, dir: &Path, out: &mut Vec<String>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for e in entries.flatten() {
        let p = e.path();
        let name = e.file_name().to_string_lossy().into_owned();
        if p.is_dir() {
            if !matches!(name.as_str(), "target" | ".git") {
                walk(root, &p, out);
            }
        } else if let Ok(rel) = p.strip_prefix(root) {
            out.push(rel.to_string_lossy().into_owned());
        }
    }
}

/// Inserts `line` as the last entry of the `catalogue!` invocation.
fn add_registry_line(mod_rs: &str, line: &str) -> Result<String, String> {
    let start = mod_rs
        .find("\ncatalogue! {")
        .ok_or("no `catalogue! {` in effects/mod.rs")?;
    let end = start + mod_rs[start..].find("\n}").ok_or("`catalogue!` does not close")?;
    Ok(format!("{}\n    {line}{}", &mod_rs[..end], &mod_rs[end..]))
}

/// Appends `row` to the effect table of docs/model.md.
fn add_docs_row(md: &str, row: &str) -> Result<String, String> {
    let section = md
        .find("## Effect catalogue")
        .ok_or("no effect catalogue in docs/model.md")?;
    let last_row = md[section..]
        .lines()
        .take_while(|l| !l.starts_with("### "))
        .filter(|l| l.starts_with("| `"))
        .last()
        .ok_or("no rows in the effect table")?;
    let at = section + md[section..].find(last_row).expect("found above") + last_row.len();
    Ok(format!("{}\n{row}{}", &md[..at], &md[at..]))
}

/// The FMU crate's manifest with its library built as an rlib alone. A
/// package that builds a cdylib gets no hash in its artifacts' names, so
/// the copy's `libhammer_fmu.rlib` and `.so` (built with nine effects)
/// would land on the workspace's own in the shared build directory, where
/// cargo still takes the workspace's as fresh: a second `cargo xtask ci` on
/// the same checkout then failed to compile hammer-diagnose, and `hammer
/// fmu`, which packs the newer of the two libraries beside it, would have
/// packed the copy's. The copy's tests load no FMU.
fn rlib_only(manifest: &str) -> Result<String, String> {
    let both = "crate-type = [\"cdylib\", \"rlib\"]";
    if manifest.matches(both).count() != 1 {
        return Err(format!("no single `{both}` in host-tools/fmu/Cargo.toml"));
    }
    Ok(manifest.replacen(both, "crate-type = [\"rlib\"]", 1))
}

pub fn run(root: &Path, totals: &mut (u64, u64)) -> Result<(), String> {
    let fixtures = root.join("xtask/fixtures/ninth-effect");
    let ws: PathBuf = root.join("target/ninth-effect/workspace");
    copy_workspace(root, &ws)?;
    write(
        &ws.join(format!("host-tools/sim/src/effects/{NAME}.rs")),
        &read(&fixtures.join("sim.rs"))?,
    )?;
    write(
        &ws.join(format!("host-tools/diagnose/src/effects/{NAME}.rs")),
        &read(&fixtures.join("diagnose.rs"))?,
    )?;
    write(
        &ws.join(format!("host-tools/diagnose/tests/{NAME}_ninth_effect.rs")),
        &read(&fixtures.join("test.rs"))?,
    )?;
    // Another version makes every workspace crate of the copy a unit of its
    // own in the shared build directory: nothing of it can stand in for the
    // workspace's (cargo would take a same-named artifact as fresh).
    let manifest = ws.join("Cargo.toml");
    let text = read(&manifest)?;
    let version = "version = \"0.1.0\"";
    if !text.contains(version) {
        return Err(format!("no `{version}` in the workspace manifest"));
    }
    // The fuzz crate is not copied (above), so it leaves the members.
    let members = ", \"fuzz\"]";
    if !text.contains(members) {
        return Err(format!("no `{members}` in the workspace manifest's members"));
    }
    write(
        &manifest,
        &text
            .replacen(version, "version = \"0.1.0-ninth-effect\"", 1)
            .replacen(members, "]", 1),
    )?;
    let fmu_manifest = ws.join("host-tools/fmu/Cargo.toml");
    write(&fmu_manifest, &rlib_only(&read(&fmu_manifest)?)?)?;
    let mod_rs = ws.join("host-tools/sim/src/effects/mod.rs");
    write(
        &mod_rs,
        &add_registry_line(&read(&mod_rs)?, &format!("{NAME}: {TYPE},"))?,
    )?;
    let model_md = ws.join("docs/model.md");
    write(
        &model_md,
        &add_docs_row(
            &read(&model_md)?,
            &format!("| `{NAME}` | `k_n_s2_per_m2` = 0.25 | `F = −k·v·abs(v)` (test effect) |"),
        )?,
    )?;
    // The workspace's build directory, where the dependencies are built
    // already; final artifacts land apart, and every library of the copy
    // has a hash of its own in its name ([`rlib_only`]), so the
    // workspace's own are not replaced. The fixture's test is the
    // diagnosis crate's: the registry reaches no further, and the CLI with
    // its MQTT and TLS stack would be built again for nothing (about 50 s
    // on 2 cores).
    // `-p hammer-unify` beside each package: cargo resolves features for the
    // selected packages alone, and without the union that crate names, 19
    // shared crates (serde, syn, libc, …) and all above them would be
    // compiled again with other features (3 minutes on 2 cores).
    // Set for these cargo calls alone: in CI the smoke run's thread is
    // alive beside them (lane.rs).
    let build_dir = crate::target_dir(root);
    let target_dir = root.join("target/ninth-effect/target");
    let envs = [
        ("CARGO_BUILD_BUILD_DIR", build_dir.as_path()),
        ("CARGO_TARGET_DIR", target_dir.as_path()),
    ];
    crate::cargo_test_with(
        &ws,
        &[
            "test",
            "--profile",
            crate::CI_PROFILE,
            "-p",
            "hammer-sim",
            "-p",
            "hammer-unify",
            "--lib",
        ],
        &envs,
        totals,
    )?;
    crate::cargo_test_with(
        &ws,
        &[
            "test",
            "--profile",
            crate::CI_PROFILE,
            "-p",
            "hammer-diagnose",
            "-p",
            "hammer-unify",
            "--test",
            &format!("{NAME}_ninth_effect"),
        ],
        &envs,
        totals,
    )
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    #[test]
    fn the_copys_fmu_crate_builds_an_rlib_alone() {
        let manifest = include_str!("../../host-tools/fmu/Cargo.toml");
        let copy = super::rlib_only(manifest).unwrap();
        assert!(copy.contains("crate-type = [\"rlib\"]"), "{copy}");
        let types: Vec<&str> = copy.lines().filter(|l| l.starts_with("crate-type")).collect();
        assert_eq!(types, ["crate-type = [\"rlib\"]"]);
        assert!(
            super::rlib_only(&copy).is_err(),
            "a manifest without the line is refused"
        );
    }

    /// The copy builds the simulator and the diagnosis with what they
    /// depend on. Of the members with a cdylib, the FMU crate is the one
    /// they reach ([`super::rlib_only`]); the others must stay leaves,
    /// which no member depends on.
    #[test]
    fn the_other_cdylib_members_are_leaves() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
        let text = |p: &Path| std::fs::read_to_string(p).unwrap();
        let workspace = text(&root.join("Cargo.toml"));
        let list = &workspace[workspace.find("members = [").unwrap()..];
        let list = &list[..list.find(']').unwrap()];
        let members: Vec<(String, String)> = list
            .split('"')
            .skip(1)
            .step_by(2)
            .map(|m| (m.to_string(), text(&root.join(m).join("Cargo.toml"))))
            .collect();
        let package = |manifest: &str| {
            let line = manifest.lines().find(|l| l.starts_with("name = ")).unwrap();
            line.split('"').nth(1).unwrap().to_string()
        };
        let cdylibs: Vec<&str> = members
            .iter()
            .filter(|(_, m)| m.contains("\"cdylib\""))
            .map(|(dir, _)| dir.as_str())
            .collect();
        assert!(cdylibs.contains(&"host-tools/fmu"), "{cdylibs:?}");
        for (dir, manifest) in members
            .iter()
            .filter(|(d, m)| d != "host-tools/fmu" && m.contains("\"cdylib\""))
        {
            let name = package(manifest);
            for (other, m) in &members {
                assert!(
                    other == dir
                        || !m.lines().any(|l| l.trim_start().starts_with(&format!("{name} "))
                            || l.trim_start().starts_with(&format!("{name}."))),
                    "{other} depends on {name}, a cdylib: the ninth effect's copy would build it"
                );
            }
        }
    }
}
