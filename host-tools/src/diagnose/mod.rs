//! `hammer diagnose` and `hammer diagnose-bench` over the `hammer-diagnose`
//! library (whose modules are re-exported here, so `diagnose::engine` is
//! the library's engine): the arguments ([`command`]), the report for
//! people ([`output`]: Markdown, terminal, figures), and a benchmark run's
//! log of finished cases, which `--resume` goes on from ([`case_log`]).

pub use hammer_diagnose::*;

pub mod case_log;
pub mod command;
pub mod output;
