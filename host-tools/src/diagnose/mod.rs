//! Sim-to-real gap diagnosis (issue 6), first part: *where* simulation and
//! measurement differ — by signal and by stage of the cycle. The stages are
//! bounded by the port events of the paper's cycle (outlets at 20 and 30 mm,
//! the impact, the direction of motion), taken from the simulated cycle.

pub mod gap;
pub mod stages;
