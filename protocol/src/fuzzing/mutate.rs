//! A small seeded generator of bad inputs for the stable smoke run: random
//! bytes now and then, otherwise a seed input with a few mutations of the
//! kinds that break decoders — a byte flipped or set to an edge value, the
//! input cut short, bytes inserted, removed or repeated, two seeds spliced,
//! an f64 overwritten with NaN, ±∞, a negative or 1.5, a varint made huge,
//! a number in a JSON line replaced by one out of range. The same seed
//! gives the same inputs, so a failure is reproducible from its seed.
//! (cargo-fuzz brings its own, coverage-guided mutations.)

/// SplitMix64: tiny, fast and good enough to pick mutations.
pub(crate) struct Mutator {
    state: u64,
}

/// Byte values decoders treat specially (varint continuation, sign bits,
/// enum tags just past the last variant).
const EDGE_BYTES: [u8; 8] = [0x00, 0x01, 0x06, 0x7f, 0x80, 0xfe, 0xff, b'"'];

const EDGE_FLOATS: [f64; 7] = [
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    -1.0,
    1.5,
    -0.0,
    f64::MAX,
];

/// Replacements for a number in a JSON line.
const EDGE_NUMBERS: [&str; 10] = [
    "-1",
    "1.5",
    "1e999",
    "-1e999",
    "4294967296",
    "18446744073709551616",
    "null",
    "\"7\"",
    "[]",
    "0.0",
];

impl Mutator {
    pub(crate) fn new(seed: u64) -> Self {
        Mutator { state: seed }
    }

    pub(crate) fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// A number in `0..n` (0 when n is 0).
    pub(crate) fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next_u64() % n as u64) as usize
        }
    }

    /// The next input: from `seeds` mostly, random bytes one time in eight
    /// (always when there are no seeds).
    pub(crate) fn input(&mut self, seeds: &[Vec<u8>]) -> Vec<u8> {
        if seeds.is_empty() || self.below(8) == 0 {
            let len = self.below(300);
            return (0..len).map(|_| self.next_u64() as u8).collect();
        }
        let mut input = seeds[self.below(seeds.len())].clone();
        for _ in 0..1 + self.below(4) {
            self.mutate(&mut input, seeds);
        }
        input
    }

    fn mutate(&mut self, input: &mut Vec<u8>, seeds: &[Vec<u8>]) {
        let len = input.len();
        let at = self.below(len + 1);
        match self.below(10) {
            0 if len > 0 => input[at.min(len - 1)] ^= 1 << self.below(8),
            1 if len > 0 => input[at.min(len - 1)] = EDGE_BYTES[self.below(EDGE_BYTES.len())],
            2 => input.truncate(at),
            3 => {
                let bytes: Vec<u8> = (0..1 + self.below(8))
                    .map(|_| self.next_u64() as u8)
                    .collect();
                input.splice(at..at, bytes);
            }
            4 => {
                let end = (at + 1 + self.below(16)).min(len);
                input.drain(at.min(end)..end);
            }
            5 => {
                let end = (at + 1 + self.below(32)).min(len);
                let copy = input[at.min(end)..end].to_vec();
                input.splice(at..at, copy);
            }
            6 => {
                let other = &seeds[self.below(seeds.len())];
                let from = self.below(other.len() + 1);
                input.truncate(at);
                input.extend_from_slice(&other[from..]);
            }
            7 if len >= 8 => {
                let at = at.min(len - 8);
                let x = EDGE_FLOATS[self.below(EDGE_FLOATS.len())];
                input[at..at + 8].copy_from_slice(&x.to_le_bytes());
            }
            8 => {
                // A length prefix or count of 2^35 or more.
                input.splice(at..at, [0xff, 0xff, 0xff, 0xff, 0x7f]);
            }
            _ => self.json_number(input),
        }
    }

    /// In text, replaces one number with an edge value; elsewhere a no-op.
    fn json_number(&mut self, input: &mut Vec<u8>) {
        let starts: Vec<usize> = (0..input.len())
            .filter(|&i| {
                input[i].is_ascii_digit() && (i == 0 || matches!(input[i - 1], b':' | b',' | b'['))
            })
            .collect();
        if starts.is_empty() {
            return;
        }
        let start = starts[self.below(starts.len())];
        let end = (start..input.len())
            .find(|&i| !matches!(input[i], b'0'..=b'9' | b'.' | b'e' | b'E' | b'-' | b'+'))
            .unwrap_or(input.len());
        let number = EDGE_NUMBERS[self.below(EDGE_NUMBERS.len())];
        input.splice(start..end, number.bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_seed_gives_the_same_inputs() {
        let seeds = vec![
            b"{\"a\":12,\"b\":[3,4]}".to_vec(),
            vec![1, 2, 3, 4, 5, 6, 7, 8, 9],
        ];
        let run = |seed| {
            let mut m = Mutator::new(seed);
            (0..200).map(|_| m.input(&seeds)).collect::<Vec<_>>()
        };
        assert_eq!(run(7), run(7));
        assert_ne!(run(7), run(8));
    }
}
