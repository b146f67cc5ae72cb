//! Reaching a broker: its URL, TLS and login ([`BrokerArgs`] as the user
//! gives them, [`Endpoint`] as a connection uses them), and a refusal read
//! out in words.

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{bail, Result};
use rumqttc::{ConnectReturnCode, ConnectionError, MqttOptions, TlsConfiguration, Transport};

use super::parse_url;
use crate::tls::Secret;

/// How to reach and log in to a broker, besides its URL: for `monitor`,
/// `demo` and `mqtt-tail` alike.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct BrokerArgs {
    /// mqtts://: the CA certificate(s), PEM, that signed the broker's
    /// certificate (default: the system's roots).
    #[arg(long, value_name = "FILE")]
    pub mqtt_ca: Option<PathBuf>,
    /// mqtts://: a client certificate, PEM, for a broker that asks for one
    /// (with --mqtt-key).
    #[arg(long, value_name = "FILE")]
    pub mqtt_cert: Option<PathBuf>,
    /// The client certificate's private key, PEM.
    #[arg(long, value_name = "FILE")]
    pub mqtt_key: Option<PathBuf>,
    /// User name on the broker. Its password comes from the environment
    /// variable HAMMER_MQTT_PASSWORD or --mqtt-password-file, never from
    /// the command line (where `ps` shows it).
    #[arg(long, value_name = "NAME")]
    pub mqtt_user: Option<String>,
    /// A file holding the --mqtt-user's password (its first line).
    #[arg(long, value_name = "FILE")]
    pub mqtt_password_file: Option<PathBuf>,
    /// mqtts:// WITHOUT checking the broker's certificate: anyone on the
    /// path can read and change the traffic. For a test broker only; every
    /// connection warns.
    #[arg(long)]
    pub mqtt_insecure_skip_verify: bool,
}

/// The environment variable holding the broker password.
pub const PASSWORD_ENV: &str = "HAMMER_MQTT_PASSWORD";

/// A broker resolved from its URL and [`BrokerArgs`]: address, TLS
/// configuration, login.
#[derive(Clone, Debug)]
pub struct Endpoint {
    pub host: String,
    pub port: u16,
    tls: Option<Arc<rustls::ClientConfig>>,
    insecure: bool,
    user: Option<String>,
    password: Option<Secret>,
}

impl Endpoint {
    pub fn resolve(url: &str, a: &BrokerArgs) -> Result<Self> {
        let (host, port, tls) = parse_url(url)?;
        let uses_tls_files =
            a.mqtt_ca.is_some() || a.mqtt_cert.is_some() || a.mqtt_key.is_some() || a.mqtt_insecure_skip_verify;
        if !tls && uses_tls_files {
            bail!("--mqtt {url}: --mqtt-ca, --mqtt-cert, --mqtt-key and --mqtt-insecure-skip-verify are for TLS: use mqtts://");
        }
        let tls = tls
            .then(|| {
                crate::tls::client_config(
                    &crate::tls::TlsFiles {
                        ca: a.mqtt_ca.clone(),
                        cert: a.mqtt_cert.clone(),
                        key: a.mqtt_key.clone(),
                        insecure: a.mqtt_insecure_skip_verify,
                    },
                    "--mqtt",
                )
            })
            .transpose()?;
        if tls.is_some() {
            crate::tls::server_name(&host)?;
        }
        let password = match (&a.mqtt_user, &a.mqtt_password_file) {
            (None, Some(_)) => bail!("--mqtt-password-file without --mqtt-user"),
            (None, None) => None,
            (Some(_), Some(f)) => Some(Secret::from_file(f, "--mqtt-password-file")?),
            (Some(_), None) => Secret::from_env(PASSWORD_ENV),
        };
        if a.mqtt_user.is_some() && password.is_some() && tls.is_none() {
            eprintln!("mqtt: the password goes to {host}:{port} unencrypted (mqtt://); use mqtts:// to a TLS listener");
        }
        Ok(Self {
            host,
            port,
            tls,
            insecure: a.mqtt_insecure_skip_verify,
            user: a.mqtt_user.clone(),
            password,
        })
    }

    /// `mqtt[s]://host:port`, for messages.
    pub fn describe(&self) -> String {
        format!(
            "{}://{}:{}",
            if self.tls.is_some() { "mqtts" } else { "mqtt" },
            self.host,
            self.port
        )
    }

    /// The client's options: address, transport, login.
    pub(super) fn options(&self, client_id: String) -> MqttOptions {
        let mut opts = MqttOptions::new(client_id, self.host.clone(), self.port);
        if let Some(cfg) = &self.tls {
            opts.set_transport(Transport::tls_with_config(TlsConfiguration::Rustls(cfg.clone())));
        }
        if let Some(user) = &self.user {
            let password = self
                .password
                .as_ref()
                .map(|p| p.expose().to_string())
                .unwrap_or_default();
            opts.set_credentials(user.clone(), password);
        }
        opts
    }

    /// The warning due at every connection, if verification is off.
    pub(super) fn connection_warning(&self) -> Option<String> {
        (self.tls.is_some() && self.insecure).then(|| crate::tls::insecure_warning(&self.describe(), "--mqtt"))
    }

    /// What a connection's failure means; `acked`: the broker had accepted
    /// the connection before it failed.
    pub(super) fn failure(&self, e: &ConnectionError, acked: bool) -> Failure {
        let at = self.describe();
        let hostport = format!("{}:{}", self.host, self.port);
        if let ConnectionError::ConnectionRefused(code) = e {
            let text = match code {
                ConnectReturnCode::BadUserNamePassword => format!(
                    "{at}: the broker refused the user name or password: check --mqtt-user and its password ({PASSWORD_ENV} or --mqtt-password-file)"
                ),
                ConnectReturnCode::NotAuthorized => format!(
                    "{at}: the broker refused the login as not authorised: check --mqtt-user and its password ({PASSWORD_ENV} or --mqtt-password-file), or the client certificate (--mqtt-cert, --mqtt-key)"
                ),
                ConnectReturnCode::BadClientId => format!("{at}: the broker refused the client id (another client with it?)"),
                other => format!("{at}: the broker refused the connection ({other:?})"),
            };
            return Failure { text, refused: true };
        }
        if let Some(r) = crate::tls::rustls_error(e) {
            return Failure {
                text: crate::tls::explain(r, &hostport, &self.host, "--mqtt", "mqtt://"),
                refused: true,
            };
        }
        if let ConnectionError::Tls(rumqttc::TlsError::Io(io)) = e {
            // Closed mid-handshake without a TLS alert: a plain listener
            // reading the ClientHello as a broken MQTT packet.
            return Failure {
                text: format!(
                    "{hostport} does not answer in TLS (the connection closed during the handshake: {io}): is it a plain listener? Use mqtt:// for it, or the broker's TLS port"
                ),
                refused: true,
            };
        }
        // The I/O error under the client's wrappers, if any.
        let mut io_kind = None;
        let mut cur: Option<&(dyn std::error::Error + 'static)> = Some(e);
        while let Some(err) = cur {
            if let Some(io) = err.downcast_ref::<std::io::Error>() {
                io_kind = Some(io.kind());
                break;
            }
            cur = err.source();
        }
        match io_kind {
            Some(std::io::ErrorKind::ConnectionRefused) => Failure {
                text: format!("{at}: nothing listens there (connection refused): is the broker running?"),
                refused: false,
            },
            _ if !acked && self.tls.is_none() && !matches!(e, ConnectionError::NetworkTimeout) => Failure {
                text: format!(
                    "{at}: the connection closed before the broker answered: if that port is a TLS listener, use mqtts:// ({e})"
                ),
                refused: true,
            },
            Some(std::io::ErrorKind::UnexpectedEof | std::io::ErrorKind::ConnectionReset) if !acked => Failure {
                text: format!(
                    "{at}: the broker closed the TLS connection before answering: it may want a client certificate (--mqtt-cert, --mqtt-key) or refuse this one"
                ),
                refused: true,
            },
            _ => Failure {
                text: format!("{at}: {e}"),
                refused: false,
            },
        }
    }
}

/// Why a connection ended, for the user: `refused` when the broker (or
/// its TLS) said no, which retrying soon will not change.
#[derive(Debug, Clone)]
pub(super) struct Failure {
    pub(super) text: String,
    pub(super) refused: bool,
}
