//! The MPU-9250's 512-byte FIFO as a fixed ring buffer (no allocation).

use crate::registers::FIFO_SIZE;

/// What happens when a byte arrives at a full FIFO (CONFIG.FIFO_MODE).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum FullPolicy {
    /// FIFO_MODE = 0: the oldest byte is discarded to make room.
    OverwriteOldest,
    /// FIFO_MODE = 1: the new byte is discarded.
    DropNew,
}

/// The FIFO bytes, oldest first, and the last byte popped (an empty FIFO repeats it).
#[derive(Debug, Clone)]
pub(crate) struct Fifo {
    buf: [u8; FIFO_SIZE],
    head: usize,
    len: usize,
    last_popped: u8,
}

impl Fifo {
    pub(crate) fn new() -> Self {
        Self {
            buf: [0; FIFO_SIZE],
            head: 0,
            len: 0,
            last_popped: 0,
        }
    }

    /// Number of bytes held.
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// Empties the FIFO (USER_CTRL.FIFO_RST, H_RESET).
    pub(crate) fn clear(&mut self) {
        self.head = 0;
        self.len = 0;
    }

    /// Appends one byte; returns `true` if the FIFO was full (the byte or the oldest one lost).
    pub(crate) fn push(&mut self, byte: u8, policy: FullPolicy) -> bool {
        if self.len == FIFO_SIZE {
            if policy == FullPolicy::DropNew {
                return true;
            }
            self.buf[self.head] = byte;
            self.head = (self.head + 1) % FIFO_SIZE;
            return true;
        }
        self.buf[(self.head + self.len) % FIFO_SIZE] = byte;
        self.len += 1;
        false
    }

    /// Removes and returns the oldest byte; an empty FIFO returns the last byte popped.
    pub(crate) fn pop(&mut self) -> u8 {
        if self.len > 0 {
            self.last_popped = self.buf[self.head];
            self.head = (self.head + 1) % FIFO_SIZE;
            self.len -= 1;
        }
        self.last_popped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fifo_order_overflow_policies_and_empty_read() {
        let mut f = Fifo::new();
        for i in 0..FIFO_SIZE {
            assert!(!f.push(i as u8, FullPolicy::DropNew));
        }
        assert_eq!(f.len(), FIFO_SIZE);
        assert!(f.push(0xEE, FullPolicy::DropNew));
        assert_eq!(f.pop(), 0); // the new byte was dropped, the oldest kept
        assert!(!f.push(0xAA, FullPolicy::OverwriteOldest)); // fills the freed slot
        assert!(f.push(0xBB, FullPolicy::OverwriteOldest)); // full again: overwrites byte 1
        assert_eq!(f.len(), FIFO_SIZE);
        assert_eq!(f.pop(), 2);
        for _ in 0..FIFO_SIZE - 3 {
            f.pop();
        }
        assert_eq!(f.pop(), 0xAA);
        assert_eq!(f.pop(), 0xBB);
        assert_eq!(f.len(), 0);
        assert_eq!(f.pop(), 0xBB); // empty: repeats the last byte
        f.push(7, FullPolicy::DropNew);
        f.clear();
        assert_eq!(f.len(), 0);
    }
}
