//! The built-in simulator as an FMI 2.0 co-simulation FMU (issue 45), and
//! the import of a foreign one (issue 46): one
//! crate builds both the FMU's shared library (cdylib) and what `hammer
//! fmu` needs to package it (rlib), from one variable table.
//!
//! Module map (data flows down the list):
//! - [`table`]: the FMU's variables: every numeric leaf of the
//!   configuration, every catalogue effect's switch and parameters, the outputs;
//! - [`instance`]: one instance's values, state machine and the run it steps
//!   ([`hammer_sim::stepper::Stepper`] and the sensor chain);
//! - [`variants`]: the second family (`hammer-variants`) behind the same instance;
//! - [`ffi`]: the C boundary, every FMI 2.0 function (panics caught, pointers checked);
//! - [`description`]: modelDescription.xml, the GUID, the configuration resource;
//! - [`package`]: the `.fmu` zip and the model map beside it;
//! - [`import`]: the other way: a foreign FMU (a bench engineer's) and its
//!   map read, checked and run behind a process boundary (issue 46).

pub mod description;
pub mod ffi;
pub mod import;
pub mod instance;
pub mod package;
pub mod table;
pub mod variants;

pub use instance::Model;
pub use package::{find_library, map_path, write_fmu, Written};
pub use variants::VariantsConfig;
