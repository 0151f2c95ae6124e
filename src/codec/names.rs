//! The `names` section (`spec/format.md` §9.2): group names, writer and readers side by side.
//!
//! Version 1 stores each name in coded group order (groups numbered by first appearance in the
//! traversal). Version 2 also stores where each coded group stood in the input, so the decoder
//! gives groups back in the input's order, and stores the names in that order as *stem +
//! number* against the previous name: CAD exporters name faces `face_1, face_2, ...` or
//! `face_141, face_171, ...`, which then cost a byte a name before deflation instead of the
//! whole string; the order then makes up most of the section.

use super::bytes::Reader;
use super::rangecoder::{BitModel, RangeDecoder};
use super::ranks::Flags;
#[cfg(any(feature = "encoder", feature = "internals"))]
use super::{bytes::put_varint, encode_below, rangecoder::RangeEncoder, zigzag64};
use super::{decode_below, unzigzag64, Budget};
use crate::error::Result;

/// Largest number a name may end in to be split as stem + number (18 decimal digits).
const MAX_NUMBER: u64 = 999_999_999_999_999_999;

/// Splits a name into a stem and the decimal number it ends in, when that number reads back
/// to the same digits (no leading zero, at most 18 digits).
#[cfg(any(feature = "encoder", feature = "internals"))]
fn split(name: &str) -> (&str, Option<u64>) {
    let digits = name.bytes().rev().take_while(u8::is_ascii_digit).count();
    let (stem, tail) = name.split_at(name.len() - digits);
    if digits == 0 || digits > 18 || (digits > 1 && tail.starts_with('0')) {
        return (name, None);
    }
    (stem, tail.parse().ok())
}

/// The rank (among the `left` unused input indices) expected for the next coded group: that
/// of the first unused index after the previous group's, wrapping to 0.
fn predicted_rank(unused: &Flags, prev: Option<u32>, left: u32) -> u32 {
    let r = prev.map_or(0, |p| unused.rank(p as usize + 1));
    if r >= left {
        0
    } else {
        r
    }
}

/// Version-2 payload: `varint order_len`, the range-coded group order (`order_len` bytes),
/// then one record per group in input order. `names[o]` is input group `o`'s name and
/// `original_of_coded[c]` the input index of coded group `c` (a permutation).
///
/// The order is coded as ranks among the input indices not yet used: one adaptive bit
/// (context: the previous bit) says whether the rank is the predicted one; otherwise its
/// distance after the prediction, `(rank - predicted - 1) mod left`, follows in direct bits.
/// Input order costs a fraction of a bit a group, an unrelated order about `log2(left)`.
#[cfg(any(feature = "encoder", feature = "internals"))]
pub fn write(names: &[&str], original_of_coded: &[u32]) -> Vec<u8> {
    let mut enc = RangeEncoder::new();
    let mut hit_models = [BitModel::default(); 2];
    let mut prev_hit = true;
    let mut unused = Flags::all(names.len());
    let mut prev = None;
    for (&o, left) in original_of_coded.iter().zip((1..=names.len() as u32).rev()) {
        let predicted = predicted_rank(&unused, prev, left);
        let actual = unused.rank(o as usize);
        let hit = actual == predicted;
        enc.encode_bit(&mut hit_models[usize::from(prev_hit)], hit);
        if !hit {
            encode_below(&mut enc, (actual + left - predicted - 1) % left, left - 1);
        }
        prev_hit = hit;
        unused.take(o as usize);
        prev = Some(o);
    }
    let order = enc.finish();
    let mut out = Vec::new();
    put_varint(&mut out, order.len() as u64);
    out.extend_from_slice(&order);
    let (mut prev_stem, mut prev_number) = ("", 0u64);
    for &name in names {
        let (stem, number) = split(name);
        match number {
            Some(n) if stem == prev_stem => {
                // Both numbers are at most MAX_NUMBER: the difference fits in 63 bits.
                let delta = n as i64 - prev_number as i64 - 1;
                put_varint(&mut out, 1 | (zigzag64(delta) << 1));
            }
            None if stem == prev_stem => put_varint(&mut out, 2),
            _ => {
                put_varint(&mut out, (stem.len() as u64) << 2);
                out.extend_from_slice(stem.as_bytes());
                put_varint(&mut out, number.map_or(0, |n| n + 1));
            }
        }
        prev_stem = stem;
        if let Some(n) = number {
            prev_number = n;
        }
    }
    out
}

/// Reads a version-2 payload for `group_count` groups: the names in input order and, for
/// every coded group, its input index. A record of a byte or two can repeat a long stem, so
/// each name is charged to `budget` before it is made.
pub(crate) fn read(
    payload: &[u8],
    group_count: usize,
    budget: &mut Budget,
) -> Result<(Vec<String>, Vec<u32>)> {
    let mut r = Reader::new(payload, "names");
    let order_len = r.varint_max("order_length", r.remaining() as u64)? as usize;
    let order = r.bytes(order_len, "order")?;
    let mut original_of_coded = Vec::with_capacity(group_count);
    {
        let mut dec = RangeDecoder::new(order, "names")?;
        let mut hit_models = [BitModel::default(); 2];
        let mut prev_hit = true;
        let mut unused = Flags::all(group_count);
        let mut prev = None;
        for left in (1..=group_count as u32).rev() {
            let predicted = predicted_rank(&unused, prev, left);
            let hit = dec.decode_bit(&mut hit_models[usize::from(prev_hit)])?;
            let rank = if hit {
                predicted
            } else {
                let d = decode_below(&mut dec, left - 1)?;
                if d >= left - 1 {
                    return Err(r.err("order", format!("rank step {d} not below {}", left - 1)));
                }
                (predicted + d + 1) % left
            };
            prev_hit = hit;
            let o = unused.select(rank);
            unused.take(o);
            original_of_coded.push(o as u32);
            prev = Some(o as u32);
        }
        dec.finish()?;
    }
    let mut names = Vec::with_capacity(group_count);
    let (mut prev_stem, mut prev_number) = (String::new(), 0u64);
    for _ in 0..group_count {
        let head = r.varint("name_head")?;
        let (stem, number) = if head & 1 == 1 {
            let n = i128::from(prev_number) + 1 + i128::from(unzigzag64(head >> 1));
            if !(0..=i128::from(MAX_NUMBER)).contains(&n) {
                return Err(r.err("name_number", format!("number {n} out of range")));
            }
            (prev_stem.clone(), Some(n as u64))
        } else if head == 2 {
            (prev_stem.clone(), None)
        } else if head & 3 == 0 {
            let len = usize::try_from(head >> 2).unwrap_or(usize::MAX);
            let b = r.bytes(len, "name_stem")?;
            let stem =
                String::from_utf8(b.to_vec()).map_err(|_| r.err("name_stem", "not UTF-8"))?;
            let n = r.varint_max("name_number", MAX_NUMBER + 1)?;
            (stem, n.checked_sub(1))
        } else {
            return Err(r.err("name_head", format!("invalid record head {head}")));
        };
        budget.charge(
            "decode memory for group names (bytes)",
            stem.len() as u64 + 20,
        )?;
        names.push(match number {
            Some(n) => format!("{stem}{n}"),
            None => stem.clone(),
        });
        prev_stem = stem;
        if let Some(n) = number {
            prev_number = n;
        }
    }
    r.expect_end()?;
    Ok((names, original_of_coded))
}

/// Version-1 payload: per coded group `varint length` + UTF-8 bytes.
pub fn read_v1(payload: &[u8], group_count: usize) -> Result<Vec<String>> {
    let mut r = Reader::new(payload, "names");
    let mut names = Vec::with_capacity(group_count.min(payload.len()));
    for _ in 0..group_count {
        let len = r.varint_max("name_length", r.remaining() as u64)?;
        let b = r.bytes(len as usize, "name")?;
        names.push(String::from_utf8(b.to_vec()).map_err(|_| r.err("name", "not UTF-8"))?);
    }
    r.expect_end()?;
    Ok(names)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_keeps_digits_that_read_back() {
        assert_eq!(split("face_12"), ("face_", Some(12)));
        assert_eq!(split("face_0"), ("face_", Some(0)));
        assert_eq!(split("face_007"), ("face_007", None));
        assert_eq!(split("12"), ("", Some(12)));
        assert_eq!(split("hub"), ("hub", None));
        assert_eq!(split(""), ("", None));
        assert_eq!(
            split("x1234567890123456789"),
            ("x1234567890123456789", None)
        );
    }

    fn round_trip(names: &[&str], order: &[u32]) -> usize {
        let payload = write(names, order);
        let (back, back_order) = read(&payload, names.len(), &mut Budget::unlimited()).unwrap();
        assert_eq!(back, names);
        assert_eq!(back_order, order);
        payload.len()
    }

    #[test]
    fn names_and_order_round_trip() {
        let seq: Vec<String> = (1..=141).map(|i| format!("face_{i}")).collect();
        let seq: Vec<&str> = seq.iter().map(String::as_str).collect();
        let identity: Vec<u32> = (0..141).collect();
        // One head byte a name; the order costs almost nothing when it is the identity.
        assert!(round_trip(&seq, &identity) < 141 + 30);
        let shuffled: Vec<u32> = (0..141).map(|i| (i * 37 + 5) % 141).collect();
        round_trip(&seq, &shuffled);
        round_trip(
            &[
                "", "hub", "hub", "face_007", "face_7", "7", "ü1", "face_3", "face_2",
            ],
            &[8, 0, 7, 1, 6, 2, 5, 3, 4],
        );
        round_trip(&[], &[]);
    }

    #[test]
    fn bad_payloads_are_errors() {
        let good = write(&["a1", "a2", "b"], &[2, 0, 1]);
        for n in 0..good.len() {
            assert!(
                read(&good[..n], 3, &mut Budget::unlimited()).is_err(),
                "prefix {n}"
            );
        }
        let mut extra = good.clone();
        extra.push(0);
        assert!(read(&extra, 3, &mut Budget::unlimited()).is_err());
        // A head with the low bits 10 other than 2 is invalid.
        let mut bad = write(&[], &[]);
        bad.push(6);
        assert!(read(&bad, 1, &mut Budget::unlimited()).is_err());
    }
}
