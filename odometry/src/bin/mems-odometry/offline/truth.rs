//! The simulated truth records of an offline run, consumed in time order as states arrive.

use std::collections::VecDeque;

use recording::Truth;

/// Truth records not yet passed by the states, in time order.
#[derive(Default)]
pub struct TruthQueue(VecDeque<Truth>);

impl TruthQueue {
    /// Takes the next truth record (they come in time order).
    pub fn push(&mut self, t: Truth) {
        self.0.push_back(t);
    }

    /// The truth at `t_ns`, dropping every earlier one (states come in time order).
    pub fn at(&mut self, t_ns: u64) -> Option<&Truth> {
        while self.0.front().is_some_and(|t| t.t_ns < t_ns) {
            self.0.pop_front();
        }
        self.0.front().filter(|t| t.t_ns == t_ns)
    }
}
