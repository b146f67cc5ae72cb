//! A test PKI made with `openssl`, as a site would make its own: a CA, a
//! server certificate for 127.0.0.1 signed by it, one for another host
//! name, a client certificate, and a second CA that signed none of them.
//! `.ci/run` installs openssl; without it the tests say so and pass only
//! outside CI.

// Each test file uses a part of it.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

pub struct Pki {
    pub ca: PathBuf,
    pub other_ca: PathBuf,
    pub server_cert: PathBuf,
    pub server_key: PathBuf,
    /// Signed by `ca`, for the name `other.example` only.
    pub wrong_name_cert: PathBuf,
    pub wrong_name_key: PathBuf,
    pub client_cert: PathBuf,
    pub client_key: PathBuf,
}

pub fn openssl_present() -> bool {
    let ok = Command::new("openssl")
        .arg("version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok();
    if !ok {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI is set but openssl is missing (.ci/run installs it)"
        );
        eprintln!("SKIPPED: openssl is not installed (apt-get install openssl)");
    }
    ok
}

fn openssl(dir: &Path, args: &[&str]) {
    let out = Command::new("openssl").current_dir(dir).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "openssl {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn ca(dir: &Path, name: &str) {
    openssl(
        dir,
        &[
            "req",
            "-x509",
            "-newkey",
            "ec",
            "-pkeyopt",
            "ec_paramgen_curve:P-256",
            "-nodes",
            "-keyout",
            &format!("{name}.key"),
            "-out",
            &format!("{name}.pem"),
            "-days",
            "2",
            "-subj",
            &format!("/CN={name}"),
            "-addext",
            "basicConstraints=critical,CA:TRUE",
            "-addext",
            "keyUsage=critical,keyCertSign,cRLSign",
        ],
    );
}

fn leaf(dir: &Path, name: &str, ca: &str, ext: &str) {
    std::fs::write(dir.join(format!("{name}.ext")), ext).unwrap();
    openssl(
        dir,
        &[
            "req",
            "-newkey",
            "ec",
            "-pkeyopt",
            "ec_paramgen_curve:P-256",
            "-nodes",
            "-keyout",
            &format!("{name}.key"),
            "-out",
            &format!("{name}.csr"),
            "-subj",
            &format!("/CN={name}"),
        ],
    );
    openssl(
        dir,
        &[
            "x509",
            "-req",
            "-in",
            &format!("{name}.csr"),
            "-CA",
            &format!("{ca}.pem"),
            "-CAkey",
            &format!("{ca}.key"),
            "-CAcreateserial",
            "-out",
            &format!("{name}.pem"),
            "-days",
            "2",
            "-extfile",
            &format!("{name}.ext"),
        ],
    );
}

/// Makes the PKI in `dir`.
pub fn make(dir: &Path) -> Pki {
    std::fs::create_dir_all(dir).unwrap();
    ca(dir, "ca");
    ca(dir, "other-ca");
    let server = "basicConstraints=CA:FALSE\nkeyUsage=critical,digitalSignature\nextendedKeyUsage=serverAuth\n";
    leaf(
        dir,
        "server",
        "ca",
        &format!("{server}subjectAltName=IP:127.0.0.1,DNS:localhost\n"),
    );
    leaf(
        dir,
        "wrong-name",
        "ca",
        &format!("{server}subjectAltName=DNS:other.example\n"),
    );
    leaf(
        dir,
        "client",
        "ca",
        "basicConstraints=CA:FALSE\nkeyUsage=critical,digitalSignature\nextendedKeyUsage=clientAuth\n",
    );
    // Mosquitto, started as root, reads them as its own user: test keys only.
    for key in ["server.key", "wrong-name.key", "client.key"] {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(dir.join(key), std::fs::Permissions::from_mode(0o644)).unwrap();
    }
    let p = |n: &str| dir.join(n);
    Pki {
        ca: p("ca.pem"),
        other_ca: p("other-ca.pem"),
        server_cert: p("server.pem"),
        server_key: p("server.key"),
        wrong_name_cert: p("wrong-name.pem"),
        wrong_name_key: p("wrong-name.key"),
        client_cert: p("client.pem"),
        client_key: p("client.key"),
    }
}

/// Every file under `dir` (recursively) and every text in `outputs` that
/// holds `secret`, by name: must be none.
pub fn holders_of(secret: &str, dir: &Path, outputs: &[(&str, &str)]) -> Vec<String> {
    let mut found = vec![];
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if let Ok(bytes) = std::fs::read(&p) {
                if bytes.windows(secret.len()).any(|w| w == secret.as_bytes()) {
                    found.push(p.display().to_string());
                }
            }
        }
    }
    for (name, text) in outputs {
        if text.contains(secret) {
            found.push(name.to_string());
        }
    }
    found
}
