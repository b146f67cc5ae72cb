//! The one TLS client configuration of the fleet links (MQTT over
//! `mqtts://`, InfluxDB over `https://`), what a failed handshake means in
//! words a user can act on, and the credentials those links carry
//! ([`Secret`]: never printed, read from the environment or a file, never
//! from the command line).
//!
//! Rules, the same for every link: the server's certificate is checked
//! against the system's roots, or against the CA file the user names
//! (`--mqtt-ca`, `--influx-ca`); a client certificate and key are offered
//! when given; verification is skipped only through a flag whose name says
//! so, and the link warns about it at every connection. rustls with the
//! `ring` provider: no OpenSSL, the same code on every host.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use rustls::client::danger::{HandshakeSignatureValid, ServerCertVerified, ServerCertVerifier};
use rustls::crypto::CryptoProvider;
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer, ServerName, UnixTime};
use rustls::{AlertDescription, CertificateError, ClientConfig, DigitallySignedStruct, RootCertStore, SignatureScheme};

/// A password or token: printed as `<redacted>`, never by value.
#[derive(Clone)]
pub struct Secret(String);

impl Secret {
    /// The value, for the one place that sends it.
    pub fn expose(&self) -> &str {
        &self.0
    }

    /// From the environment variable `var`, if set and not empty.
    pub fn from_env(var: &str) -> Option<Self> {
        std::env::var(var).ok().filter(|v| !v.is_empty()).map(Self)
    }

    /// A file's first line (its newline is not part of it); `flag` names
    /// the option in messages.
    pub fn from_file(path: &Path, flag: &str) -> Result<Self> {
        let text = std::fs::read_to_string(path).with_context(|| format!("{flag} {}", path.display()))?;
        let first = text.lines().next().unwrap_or("");
        if first.is_empty() {
            bail!("{flag} {}: its first line is empty", path.display());
        }
        Ok(Self(first.to_string()))
    }
}

impl std::fmt::Debug for Secret {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("<redacted>")
    }
}

/// What a link's TLS is built from; `flag` is the option prefix the user
/// typed (`--mqtt`, `--influx`), so messages name the options to check.
#[derive(Debug, Clone, Default)]
pub struct TlsFiles {
    pub ca: Option<PathBuf>,
    pub cert: Option<PathBuf>,
    pub key: Option<PathBuf>,
    /// No verification of the server's certificate (the flag says so).
    pub insecure: bool,
}

/// A URL as a message may show it: the user information before `@` and the
/// values of query parameters that carry secrets (`p`, `password`, `token`)
/// replaced by `<redacted>`. A refusal of a URL that holds credentials must
/// not print them: messages land in logs and terminals.
pub fn redacted_url(url: &str) -> String {
    let (scheme, rest) = match url.find("://") {
        Some(i) => url.split_at(i + 3),
        None => ("", url),
    };
    let end = rest.find(['/', '?', '#']).unwrap_or(rest.len());
    let (authority, tail) = rest.split_at(end);
    let authority = match authority.rfind('@') {
        Some(i) => format!("<redacted>{}", &authority[i..]),
        None => authority.to_string(),
    };
    let tail = match tail.split_once('?') {
        Some((path, query)) => {
            let (query, fragment) = query.split_once('#').map_or((query, None), |(q, f)| (q, Some(f)));
            let kept: Vec<String> = query
                .split('&')
                .map(|kv| match kv.split_once('=') {
                    Some((k, _)) if matches!(k, "p" | "password" | "token") => format!("{k}=<redacted>"),
                    _ => kv.to_string(),
                })
                .collect();
            let fragment = fragment.map(|f| format!("#{f}")).unwrap_or_default();
            format!("{path}?{}{fragment}", kept.join("&"))
        }
        None => tail.to_string(),
    };
    format!("{scheme}{authority}{tail}")
}

/// The warning a link without verification gives at every connection.
pub fn insecure_warning(endpoint: &str, flag: &str) -> String {
    format!(
        "WARNING {endpoint}: TLS without checking the server's certificate ({flag}-insecure-skip-verify): \
         anyone on the path can read and change this traffic"
    )
}

fn provider() -> Arc<CryptoProvider> {
    Arc::new(rustls::crypto::ring::default_provider())
}

fn read_certs(path: &Path, what: &str) -> Result<Vec<CertificateDer<'static>>> {
    let bytes = std::fs::read(path).with_context(|| format!("{what} {}", path.display()))?;
    let certs = CertificateDer::pem_slice_iter(&bytes)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| anyhow::anyhow!("{what} {}: not PEM certificates ({e})", path.display()))?;
    if certs.is_empty() {
        bail!(
            "{what} {}: no certificate in it (a PEM file with -----BEGIN CERTIFICATE-----)",
            path.display()
        );
    }
    Ok(certs)
}

/// The client configuration for `files`: roots, optional client
/// certificate, optional verification bypass.
pub fn client_config(files: &TlsFiles, flag: &str) -> Result<Arc<ClientConfig>> {
    let provider = provider();
    let builder = ClientConfig::builder_with_provider(provider.clone())
        .with_safe_default_protocol_versions()
        .context("TLS protocol versions")?;
    let builder = if files.insecure {
        builder
            .dangerous()
            .with_custom_certificate_verifier(Arc::new(NoVerification(provider)))
    } else {
        let mut roots = RootCertStore::empty();
        match &files.ca {
            Some(ca) => {
                let (added, _) = roots.add_parsable_certificates(read_certs(ca, &format!("{flag}-ca"))?);
                if added == 0 {
                    bail!("{flag}-ca {}: no usable CA certificate in it", ca.display());
                }
            }
            None => {
                let found = rustls_native_certs::load_native_certs();
                roots.add_parsable_certificates(found.certs);
                if roots.is_empty() {
                    bail!(
                        "no system CA certificates found (Debian: apt-get install ca-certificates); \
                         or name the CA that signed the server's certificate with {flag}-ca FILE"
                    );
                }
            }
        }
        builder.with_root_certificates(roots)
    };
    let config = match (&files.cert, &files.key) {
        (Some(cert), Some(key)) => {
            let certs = read_certs(cert, &format!("{flag}-cert"))?;
            let key = PrivateKeyDer::from_pem_file(key).map_err(|e| {
                anyhow::anyhow!(
                    "{flag}-key {}: no private key read ({e}); a PEM key (PKCS#8, PKCS#1 or SEC1)",
                    key.display()
                )
            })?;
            builder
                .with_client_auth_cert(certs, key)
                .with_context(|| format!("{flag}-cert {} with {flag}-key", cert.display()))?
        }
        (None, None) => builder.with_no_client_auth(),
        _ => bail!("{flag}-cert and {flag}-key go together"),
    };
    Ok(Arc::new(config))
}

/// A server name for the handshake, from the host the user gave.
pub fn server_name(host: &str) -> Result<ServerName<'static>> {
    ServerName::try_from(host.to_string()).with_context(|| format!("{host:?} is not a host name or address"))
}

/// Accepts any certificate, still checking the handshake's signatures:
/// only behind `…-insecure-skip-verify`.
#[derive(Debug)]
struct NoVerification(Arc<CryptoProvider>);

impl ServerCertVerifier for NoVerification {
    fn verify_server_cert(
        &self,
        _end_entity: &CertificateDer<'_>,
        _intermediates: &[CertificateDer<'_>],
        _server_name: &ServerName<'_>,
        _ocsp_response: &[u8],
        _now: UnixTime,
    ) -> Result<ServerCertVerified, rustls::Error> {
        Ok(ServerCertVerified::assertion())
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls12_signature(message, cert, dss, &self.0.signature_verification_algorithms)
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        rustls::crypto::verify_tls13_signature(message, cert, dss, &self.0.signature_verification_algorithms)
    }

    fn supported_verify_schemes(&self) -> Vec<SignatureScheme> {
        self.0.signature_verification_algorithms.supported_schemes()
    }
}

/// The rustls error somewhere in `e`'s chain (also inside an `io::Error`,
/// whose `source` skips the error it wraps).
pub fn rustls_error<'a>(e: &'a (dyn std::error::Error + 'static)) -> Option<&'a rustls::Error> {
    let mut cur = Some(e);
    while let Some(e) = cur {
        if let Some(r) = e.downcast_ref::<rustls::Error>() {
            return Some(r);
        }
        if let Some(r) = e
            .downcast_ref::<std::io::Error>()
            .and_then(|io| io.get_ref())
            .and_then(|inner| inner.downcast_ref::<rustls::Error>())
        {
            return Some(r);
        }
        cur = e.source();
    }
    None
}

/// A TLS failure in words: what is wrong and what to check. `endpoint` is
/// `host:port`, `flag` the option prefix (`--mqtt`, `--influx`), `plain`
/// the scheme without TLS (`mqtt://`, `http://`).
pub fn explain(e: &rustls::Error, endpoint: &str, host: &str, flag: &str, plain: &str) -> String {
    use rustls::Error as E;
    match e {
        E::InvalidCertificate(c) => match c {
            CertificateError::UnknownIssuer | CertificateError::BadSignature => format!(
                "{endpoint}: the server's certificate is not signed by a CA this host trusts; \
                 check {flag}-ca (the CA that signed the server's certificate; without it the system's roots are used)"
            ),
            CertificateError::NotValidForName | CertificateError::NotValidForNameContext { .. } => format!(
                "{endpoint}: the server's certificate is for another name than {host:?}; \
                 connect by a name on its certificate, or have it issued with {host} as a subject alternative name"
            ),
            CertificateError::Expired | CertificateError::ExpiredContext { .. } => format!(
                "{endpoint}: the server's certificate has expired; renew it on the server (and check this host's clock)"
            ),
            CertificateError::NotValidYet | CertificateError::NotValidYetContext { .. } => {
                format!("{endpoint}: the server's certificate is not valid yet; check this host's clock")
            }
            other => format!("{endpoint}: the server's certificate is refused ({other:?})"),
        },
        E::AlertReceived(a) => match a {
            AlertDescription::CertificateRequired => {
                format!("{endpoint}: the server requires a client certificate; give {flag}-cert and {flag}-key")
            }
            AlertDescription::BadCertificate
            | AlertDescription::UnknownCA
            | AlertDescription::CertificateUnknown
            | AlertDescription::UnsupportedCertificate
            | AlertDescription::CertificateExpired
            | AlertDescription::CertificateRevoked
            | AlertDescription::AccessDenied => format!(
                "{endpoint}: the server rejected the client certificate ({a:?}); check {flag}-cert and {flag}-key \
                 (signed by a CA the server trusts, not expired) or give them if the server requires one"
            ),
            AlertDescription::HandshakeFailure | AlertDescription::ProtocolVersion => format!(
                "{endpoint}: the server ended the TLS handshake ({a:?}): no common protocol or cipher, \
                 or it requires a client certificate ({flag}-cert, {flag}-key)"
            ),
            other => format!("{endpoint}: the server ended the TLS session ({other:?})"),
        },
        E::InvalidMessage(_) | E::InappropriateMessage { .. } | E::InappropriateHandshakeMessage { .. } => format!(
            "{endpoint} does not answer in TLS: is it a plain listener? Use {plain} for it, or the server's TLS port"
        ),
        other => format!("{endpoint}: TLS failed: {other}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_url_is_shown_without_its_credentials() {
        assert_eq!(
            redacted_url("mqtts://u:hunter2@broker:8883"),
            "mqtts://<redacted>@broker:8883"
        );
        assert_eq!(
            redacted_url("https://a:b@h:8086/write?db=x&p=hunter2#f"),
            "https://<redacted>@h:8086/write?db=x&p=<redacted>#f"
        );
        assert_eq!(
            redacted_url("http://h/api/v2/write?token=t0k&org=o"),
            "http://h/api/v2/write?token=<redacted>&org=o"
        );
        assert_eq!(redacted_url("mqtt://broker:1883"), "mqtt://broker:1883");
        assert_eq!(redacted_url("u:pw@host"), "<redacted>@host");
    }

    #[test]
    fn a_missing_or_empty_ca_file_is_named() {
        let dir = std::env::temp_dir().join(format!("hammer-tls-unit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let empty = dir.join("empty.pem");
        std::fs::write(&empty, "not a certificate\n").unwrap();
        let e = client_config(
            &TlsFiles {
                ca: Some(empty.clone()),
                ..Default::default()
            },
            "--mqtt",
        )
        .unwrap_err();
        assert!(
            format!("{e:#}").contains("--mqtt-ca") && format!("{e:#}").contains("empty.pem"),
            "{e:#}"
        );
        let e = client_config(
            &TlsFiles {
                ca: Some(dir.join("absent.pem")),
                ..Default::default()
            },
            "--influx",
        )
        .unwrap_err();
        assert!(format!("{e:#}").contains("--influx-ca"), "{e:#}");
        let e = client_config(
            &TlsFiles {
                cert: Some(empty),
                insecure: true,
                ..Default::default()
            },
            "--mqtt",
        )
        .unwrap_err();
        assert!(format!("{e:#}").contains("go together"), "{e:#}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn handshake_failures_name_what_to_check() {
        let unknown = rustls::Error::InvalidCertificate(CertificateError::UnknownIssuer);
        let io = std::io::Error::new(std::io::ErrorKind::InvalidData, unknown);
        let found = rustls_error(&io).expect("found inside io::Error");
        let text = explain(found, "b:8883", "b", "--mqtt", "mqtt://");
        assert!(text.contains("--mqtt-ca") && text.contains("b:8883"), "{text}");
        let name = rustls::Error::InvalidCertificate(CertificateError::NotValidForName);
        assert!(explain(&name, "b:8883", "b", "--mqtt", "mqtt://").contains("another name"));
        let plain = rustls::Error::InvalidMessage(rustls::InvalidMessage::InvalidContentType);
        assert!(explain(&plain, "b:1883", "b", "--mqtt", "mqtt://").contains("plain listener"));
        let cert = rustls::Error::AlertReceived(AlertDescription::CertificateRequired);
        assert!(explain(&cert, "b:8883", "b", "--mqtt", "mqtt://").contains("--mqtt-cert"));
    }
}
