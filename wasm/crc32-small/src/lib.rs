//! CRC-32 (IEEE 802.3, reflected polynomial 0xEDB88320): the subset of the `crc32fast` API that
//! `scode` and `flate2` use, bytewise with one 256-entry table built at compile time.
#![forbid(unsafe_code)]
#![no_std]

const POLY: u32 = 0xEDB8_8320;

const TABLE: [u32; 256] = {
    let mut t = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 { (c >> 1) ^ POLY } else { c >> 1 };
            k += 1;
        }
        t[i] = c;
        i += 1;
    }
    t
};

fn update(state: u32, data: &[u8]) -> u32 {
    let mut c = !state;
    for &b in data {
        c = TABLE[((c ^ b as u32) & 0xFF) as usize] ^ (c >> 8);
    }
    !c
}

/// `a * b mod P` for bit-reflected polynomials (zlib's `multmodp`).
fn mult_mod_p(a: u32, mut b: u32) -> u32 {
    let mut m = 1u32 << 31;
    let mut p = 0u32;
    loop {
        if a & m != 0 {
            p ^= b;
            if a & (m - 1) == 0 {
                break;
            }
        }
        m >>= 1;
        b = if b & 1 != 0 { (b >> 1) ^ POLY } else { b >> 1 };
    }
    p
}

/// `x^(8 len) mod P` (zlib's `x2nmodp(len, 3)`), by squaring.
fn x8n_mod_p(mut len: u64) -> u32 {
    let mut p = 1u32 << 31; // x^0
    let mut k = 3u32;
    while len != 0 {
        // x^(2^k) by repeated squaring of x^1 (0x40000000)
        if len & 1 != 0 {
            let mut x2k = 1u32 << 30;
            for _ in 0..k {
                x2k = mult_mod_p(x2k, x2k);
            }
            p = mult_mod_p(x2k, p);
        }
        len >>= 1;
        k += 1;
    }
    p
}

/// CRC-32 of `data`.
pub fn hash(data: &[u8]) -> u32 {
    update(0, data)
}

/// Incremental CRC-32.
#[derive(Clone, Debug, Default)]
pub struct Hasher {
    state: u32,
    amount: u64,
}

impl Hasher {
    pub fn new() -> Self {
        Self::default()
    }
    pub fn new_with_initial(init: u32) -> Self {
        Self::new_with_initial_len(init, 0)
    }
    pub fn new_with_initial_len(init: u32, amount: u64) -> Self {
        Hasher {
            state: init,
            amount,
        }
    }
    pub fn update(&mut self, data: &[u8]) {
        self.state = update(self.state, data);
        self.amount += data.len() as u64;
    }
    pub fn finalize(self) -> u32 {
        self.state
    }
    pub fn reset(&mut self) {
        self.state = 0;
        self.amount = 0;
    }
    /// Makes this the CRC of this hasher's bytes followed by `other`'s.
    pub fn combine(&mut self, other: &Self) {
        self.state = mult_mod_p(x8n_mod_p(other.amount), self.state) ^ other.state;
        self.amount += other.amount;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_answers() {
        assert_eq!(hash(b""), 0);
        assert_eq!(hash(b"123456789"), 0xCBF4_3926);
        assert_eq!(
            hash(b"The quick brown fox jumps over the lazy dog"),
            0x414F_A339
        );
    }

    #[test]
    fn incremental_and_combined_match_one_shot() {
        let data: [u8; 300] = core::array::from_fn(|i| (i * 37 % 251) as u8);
        for split in [0, 1, 7, 64, 150, 299, 300] {
            let (a, b) = data.split_at(split);
            let mut h = Hasher::new();
            h.update(a);
            h.update(b);
            assert_eq!(h.clone().finalize(), hash(&data));
            let (mut ha, mut hb) = (Hasher::new(), Hasher::new());
            ha.update(a);
            hb.update(b);
            ha.combine(&hb);
            assert_eq!(ha.finalize(), hash(&data), "split {split}");
        }
    }
}
