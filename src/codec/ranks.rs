//! Order statistics over `0..n` with a Fenwick tree of flags: how many set flags lie below
//! an index, and which set index has a given number of set flags below it, both in
//! O(log n). Names code the group order as ranks among unused input indices (§9.2); version
//! 3 groups code an already used group by its recency rank (§6.5). Both sides of the codec
//! need exactly these queries, and a plain scan would make hostile files quadratic.

pub struct Flags {
    tree: Vec<u32>,
    top: usize,
}

impl Flags {
    /// `n` flags, all set.
    pub fn all(n: usize) -> Self {
        let mut tree = vec![0u32; n + 1];
        for i in 1..=n {
            tree[i] += 1;
            let j = i + (i & i.wrapping_neg());
            if j <= n {
                tree[j] += tree[i];
            }
        }
        Flags {
            tree,
            top: Self::top_of(n),
        }
    }

    /// `n` flags, none set.
    pub fn none(n: usize) -> Self {
        Flags {
            tree: vec![0u32; n + 1],
            top: Self::top_of(n),
        }
    }

    fn top_of(n: usize) -> usize {
        if n == 0 {
            0
        } else {
            1 << (usize::BITS - 1 - n.leading_zeros())
        }
    }

    /// Number of set flags below `x` (`x <= n`).
    pub fn rank(&self, x: usize) -> u32 {
        let (mut i, mut s) = (x, 0);
        while i > 0 {
            s += self.tree[i];
            i &= i - 1;
        }
        s
    }

    /// The set index with `k` set flags below it (`k` < number set).
    pub fn select(&self, mut k: u32) -> usize {
        let (mut pos, mut step) = (0usize, self.top);
        while step > 0 {
            let next = pos + step;
            if next < self.tree.len() && self.tree[next] <= k {
                pos = next;
                k -= self.tree[next];
            }
            step >>= 1;
        }
        pos
    }

    /// Clears the (set) flag `x`.
    pub fn take(&mut self, x: usize) {
        let mut i = x + 1;
        while i < self.tree.len() {
            self.tree[i] -= 1;
            i += i & i.wrapping_neg();
        }
    }

    /// Sets the (clear) flag `x`.
    pub fn put(&mut self, x: usize) {
        let mut i = x + 1;
        while i < self.tree.len() {
            self.tree[i] += 1;
            i += i & i.wrapping_neg();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranks_and_selects() {
        let mut u = Flags::all(10);
        u.take(3);
        u.take(0);
        assert_eq!(u.rank(4), 2);
        assert_eq!(u.select(0), 1);
        assert_eq!(u.select(2), 4);
        assert_eq!(u.select(7), 9);
        let e = Flags::all(0);
        assert_eq!(e.rank(0), 0);
        let mut s = Flags::none(9);
        for x in [7, 2, 5] {
            s.put(x);
        }
        s.take(5);
        assert_eq!(s.rank(8), 2);
        assert_eq!((s.select(0), s.select(1)), (2, 7));
    }
}
