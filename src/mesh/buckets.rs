//! Items grouped by a small integer key, in two flat arrays.

/// Items by key: `items[offsets[k]..offsets[k + 1]]` are key `k`'s, in the order given.
/// Two flat arrays rather than a `Vec` per key: built once over every face or vertex of a
/// mesh and read many times, it takes two allocations.
#[derive(Clone, Debug, Default)]
pub struct Buckets {
    offsets: Vec<u32>,
    items: Vec<u32>,
}

impl Buckets {
    /// Buckets of keys `0..keys` from the `(key, item)` pairs `pairs()` yields (called twice:
    /// to count, then to fill). A key at or beyond `keys` is left out.
    pub fn new<I: Iterator<Item = (u32, u32)>>(keys: usize, pairs: impl Fn() -> I) -> Self {
        let mut offsets = vec![0u32; keys + 1];
        for (k, _) in pairs() {
            if let Some(n) = offsets
                .get_mut(k as usize + 1)
                .filter(|_| (k as usize) < keys)
            {
                *n += 1;
            }
        }
        for k in 0..keys {
            offsets[k + 1] += offsets[k];
        }
        let mut fill = offsets.clone();
        let mut items = vec![0u32; offsets[keys] as usize];
        for (k, item) in pairs().filter(|&(k, _)| (k as usize) < keys) {
            items[fill[k as usize] as usize] = item;
            fill[k as usize] += 1;
        }
        Buckets { offsets, items }
    }

    /// The items of `key` (none beyond the last key).
    pub fn of(&self, key: usize) -> &[u32] {
        match self.offsets.get(key..key + 2) {
            Some(r) => &self.items[r[0] as usize..r[1] as usize],
            None => &[],
        }
    }

    /// How many keys there are.
    pub fn keys(&self) -> usize {
        self.offsets.len() - 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn items_keep_their_order_within_a_key() {
        let pairs = [(2, 10), (0, 11), (2, 12), (5, 13), (0, 14)];
        let b = Buckets::new(3, || pairs.iter().copied());
        assert_eq!(b.keys(), 3);
        assert_eq!(b.of(0), &[11, 14]);
        assert!(b.of(1).is_empty());
        assert_eq!(b.of(2), &[10, 12]);
        assert!(b.of(3).is_empty());
    }
}
