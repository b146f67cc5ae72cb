//! `hammer diagnose` and `hammer diagnose-bench` over the `hammer-diagnose`
//! library (whose modules are re-exported here, so `diagnose::engine` is
//! the library's engine): the arguments ([`command`]) and the report for
//! people ([`output`]: Markdown, terminal, figures).

pub use hammer_diagnose::*;

pub mod command;
pub mod output;
