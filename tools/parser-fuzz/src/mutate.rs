//! The mutations: libFuzzer's basic byte operators (bit flips, random and interesting bytes,
//! deletions, duplications, truncation, splicing with another seed, interesting 64-bit
//! integers written over the bytes) and two for text formats (a number replaced by NaN,
//! infinities, huge, tiny or out-of-range values; a line repeated).
//!
//! Hand-written because no stable-Rust crate mutates seed files: cargo-fuzz (libFuzzer) needs
//! nightly, and `arbitrary` / `proptest` build values from scratch, which rarely gets past a
//! format's header, checksums and compression to the checks under test; mutating valid files
//! does.

use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Number texts a numeric cell is replaced by: non-finite, huge, subnormal, beyond the sensor's
/// range, beyond `u64`, negative zero, and an hour in seconds.
const NUMBERS: [&str; 16] = [
    "NaN",
    "inf",
    "-inf",
    "1e300",
    "-1e300",
    "1e-320",
    "100",
    "-100",
    "0",
    "-0",
    "3600",
    "18446744073709551616",
    "99999999999999999999.5",
    "1e",
    "--1",
    ".",
];

/// 64-bit values written over 8 bytes: lengths and sizes at the edges of their types, and the
/// size field that once asked for 7.3e18 bytes.
const INTEGERS: [u64; 8] = [
    0,
    1,
    0xff,
    0xffff_ffff,
    0x7fff_ffff_ffff_ffff,
    u64::MAX,
    0x6500_0000_0000_0000,
    1 << 32,
];

/// Bytes that matter to the text formats.
const BYTES: &[u8] = b"\n\r,.-+e#\"0 9\0\xff";

/// One of `seeds`, mutated 1 to 4 times.
pub fn mutate(seeds: &[Vec<u8>], rng: &mut ChaCha8Rng) -> Vec<u8> {
    let mut data = seeds[rng.random_range(0..seeds.len())].clone();
    for _ in 0..rng.random_range(1..=4) {
        apply(&mut data, seeds, rng);
    }
    data
}

/// Applies one randomly chosen mutation.
fn apply(data: &mut Vec<u8>, seeds: &[Vec<u8>], rng: &mut ChaCha8Rng) {
    if data.is_empty() {
        data.push(BYTES[rng.random_range(0..BYTES.len())]);
        return;
    }
    let len = data.len();
    let at = rng.random_range(0..len);
    match rng.random_range(0..10) {
        0 => data[at] ^= 1 << rng.random_range(0..8),
        1 => data[at] = rng.random(),
        2 => data[at] = BYTES[rng.random_range(0..BYTES.len())],
        3 => {
            let end = (at + rng.random_range(1..=16)).min(len);
            data.drain(at..end);
        }
        4 => {
            let from = rng.random_range(0..len);
            let end = (from + rng.random_range(1..=64)).min(len);
            let copy = data[from..end].to_vec();
            data.splice(at..at, copy);
        }
        5 => data.truncate(at),
        6 => {
            let other = &seeds[rng.random_range(0..seeds.len())];
            let from = rng.random_range(0..other.len().max(1));
            data.truncate(at);
            data.extend_from_slice(other.get(from..).unwrap_or_default());
        }
        7 => {
            let value = INTEGERS[rng.random_range(0..INTEGERS.len())];
            let bytes = value.to_le_bytes();
            let end = (at + 8).min(len);
            data[at..end].copy_from_slice(&bytes[..end - at]);
        }
        8 => replace_number(data, at, rng),
        _ => repeat_line(data, at),
    }
}

/// Replaces the number (a run of digits, `.`, `e`, `+`, `-`) at or after `at` by one of
/// [`NUMBERS`].
fn replace_number(data: &mut Vec<u8>, at: usize, rng: &mut ChaCha8Rng) {
    let is_number = |b: &u8| b.is_ascii_digit() || b".eE+-".contains(b);
    let Some(start) = data[at..]
        .iter()
        .position(u8::is_ascii_digit)
        .map(|p| at + p)
    else {
        return;
    };
    let start = start
        - data[..start]
            .iter()
            .rev()
            .take_while(|b| is_number(b))
            .count();
    let end = start + data[start..].iter().take_while(|b| is_number(b)).count();
    let text = NUMBERS[rng.random_range(0..NUMBERS.len())];
    data.splice(start..end, text.bytes());
}

/// Repeats the line that holds byte `at`.
fn repeat_line(data: &mut Vec<u8>, at: usize) {
    let start = data[..at]
        .iter()
        .rposition(|&b| b == b'\n')
        .map_or(0, |p| p + 1);
    let end = data[at..]
        .iter()
        .position(|&b| b == b'\n')
        .map_or(data.len(), |p| at + p + 1);
    let line = data[start..end].to_vec();
    data.splice(end..end, line);
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn the_same_rng_gives_the_same_input_and_inputs_differ() {
        let seeds = vec![b"t_s,ax_g\n0.5,1.25\n1.5,-2e-3\n".to_vec()];
        let run = |seed| mutate(&seeds, &mut ChaCha8Rng::seed_from_u64(seed));
        assert_eq!(run(7), run(7));
        let distinct: std::collections::HashSet<Vec<u8>> = (0..200).map(run).collect();
        assert!(distinct.len() > 150, "{} distinct of 200", distinct.len());
    }

    #[test]
    fn a_number_is_replaced_whole_and_a_line_repeated() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut data = b"a,12.5e-3,b\n".to_vec();
        replace_number(&mut data, 4, &mut rng);
        let text = String::from_utf8_lossy(&data).into_owned();
        assert!(text.starts_with("a,") && text.ends_with(",b\n"), "{text}");
        assert!(
            NUMBERS.iter().any(|n| text == format!("a,{n},b\n")),
            "{text}"
        );
        let mut data = b"x\nyz\n".to_vec();
        repeat_line(&mut data, 3);
        assert_eq!(data, b"x\nyz\nyz\n");
    }
}
