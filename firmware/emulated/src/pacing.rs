//! Keeps the app's sampling loop turning while no samples arrive.
//!
//! `hammer_app::sampling` applies commands and sends its periodic status
//! between sample blocks. On this board samples come only from the host, so
//! without them a `Hello` would never be answered and no status sent. This
//! source hands the loop an empty block whenever a command is waiting or the
//! idle tick passes; an empty block changes nothing in the monitor.

use embassy_futures::select::{select3, Either3};
use embassy_sync::blocking_mutex::raw::RawMutex;
use hammer_app::{Overrun, SampleSource, Shared};
use hammer_estimator::RawSample;

use crate::clock;

pub struct Paced<'a, S, M: RawMutex> {
    inner: S,
    shared: &'a Shared<M>,
}

impl<'a, S: SampleSource, M: RawMutex> Paced<'a, S, M> {
    /// `inner` must be cancel-safe: its read is dropped when another event
    /// wins. `LinkSamples` is: it only ever waits for a whole block.
    pub fn new(inner: S, shared: &'a Shared<M>) -> Self {
        Self { inner, shared }
    }
}

impl<S: SampleSource, M: RawMutex> SampleSource for Paced<'_, S, M> {
    async fn read(&mut self, buf: &mut [RawSample]) -> Result<usize, Overrun> {
        // The sampling loop is the commands channel's only receiver, so this
        // wait does not take the channel's receive waker from anyone.
        let commands = self.shared.commands.ready_to_receive();
        match select3(self.inner.read(buf), commands, clock::next_tick(clock::Waiter::Pacing)).await {
            Either3::First(r) => r,
            Either3::Second(()) | Either3::Third(()) => Ok(0),
        }
    }
}
