//! `hammer-fleet`, the fleet sinks: where the cycle reports go beyond the
//! bench (files, a broker, a time-series database), apart from the CLI so a
//! fleet gateway or a script can use them without the dashboard.
//!
//! Module map (each row uses only the rows above it and the crates below):
//! - [`records`]: every rendering of a cycle report, from
//!   `hammer_types::fields::FIELDS`: text, and the columns the sinks write;
//! - [`private_files`]: owner-only directories and files that do not follow
//!   symlinks (the outage buffer, the logs);
//! - [`tls`]: the one TLS client configuration (MQTT over TLS, InfluxDB over
//!   HTTPS) and handshake failures in words;
//! - [`parquet_files`], [`influx`]: cycle reports as Parquet files and as
//!   line protocol, written to a file or InfluxDB's HTTP API;
//! - [`mqtt`]: publishing to a broker, with the outage buffer on disk.

pub mod influx;
pub mod mqtt;
pub mod parquet_files;
pub mod private_files;
pub mod records;
pub mod tls;
