//! A fixed-capacity delay line (ring buffer): allocation only at construction.

/// Keeps the last `capacity` values pushed; before enough pushes it repeats the initial value
/// (a signal that held its initial value for all earlier time).
#[derive(Debug, Clone)]
pub struct DelayLine<T: Copy> {
    buffer: Vec<T>,
    head: usize,
}

impl<T: Copy> DelayLine<T> {
    /// A line holding `max_lag + 1` values, all `initial`.
    pub fn new(max_lag: usize, initial: T) -> Self {
        DelayLine {
            buffer: vec![initial; max_lag + 1],
            head: 0,
        }
    }

    /// Sets every stored value to `value` (the signal held it for all earlier time); does not
    /// allocate.
    pub fn fill(&mut self, value: T) {
        self.buffer.fill(value);
    }

    /// Appends the newest value, dropping the oldest.
    pub fn push(&mut self, value: T) {
        self.head = (self.head + 1) % self.buffer.len();
        self.buffer[self.head] = value;
    }

    /// The value pushed `lag` pushes ago (0 = newest); `lag` is clamped to the capacity.
    pub fn delayed(&self, lag: usize) -> T {
        let n = self.buffer.len();
        let lag = lag.min(n - 1);
        self.buffer[(self.head + n - lag) % n]
    }
}

#[cfg(test)]
mod tests {
    use super::DelayLine;

    #[test]
    fn returns_values_from_lag_pushes_ago() {
        let mut line = DelayLine::new(3, -1);
        assert_eq!(line.delayed(3), -1);
        for v in 0..10 {
            line.push(v);
            assert_eq!(line.delayed(0), v);
            assert_eq!(line.delayed(2), if v >= 2 { v - 2 } else { -1 });
        }
    }
}
