//! Writing to standard output without panicking: `println!` panics when
//! stdout is closed or full (`hammer … | head -1`, `> /dev/full`); these
//! return an error the CLI reports instead. Declared first in `lib.rs` so
//! every module sees them.

/// `println!` that returns an error instead of panicking when standard
/// output is closed or full (`hammer … | head -1`, `> /dev/full`).
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout().lock(), $($arg)*).map_err(|e| anyhow::Error::new(e).context("writing to standard output"))?
    }};
}

/// `print!` that returns an error instead of panicking (see [`outln!`]).
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        write!(std::io::stdout().lock(), $($arg)*).map_err(|e| anyhow::Error::new(e).context("writing to standard output"))?
    }};
}
