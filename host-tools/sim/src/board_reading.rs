//! A file's codes as a board reports them: the estimator, then the
//! chambers' reader (`hammer_app::chambers::Pipeline`), the same bytes as
//! the board's on the same codes. What `hammer estimate` and the Python
//! package give; the diagnosis keeps the estimator alone
//! ([`crate::estimation::run`]).

use hammer_app::chambers::{Pipeline, ReaderRoom};
use hammer_estimator::{Config, CycleReport, RawSample};
use hammer_trace::trace::Gap;

use crate::estimation::{between_gaps, refused};
use hammer_trace::config::ConfigError;

/// The pipeline for `c`.
pub fn pipeline(c: Config) -> Result<Pipeline<Box<ReaderRoom>>, ConfigError> {
    Pipeline::new(c, Box::<ReaderRoom>::default()).map_err(refused)
}

/// [`crate::estimation::run_with_gaps`] as a board reports: each gap told
/// to the estimator where it falls; the last cycle, whose 8 ms after it the
/// codes do not hold, unread.
pub fn run_with_gaps(samples: &[RawSample], gaps: &[Gap], c: Config) -> Result<Vec<CycleReport>, ConfigError> {
    let mut p = pipeline(c)?;
    let mut out = Vec::new();
    between_gaps(samples, gaps, |part, missing| {
        p.push_block(part, &mut |r| out.push(r));
        if let Some(n) = missing {
            p.push_gap(n);
        }
    });
    p.finish(&mut |r| out.push(r));
    Ok(out)
}
