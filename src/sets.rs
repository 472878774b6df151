//! Disjoint sets (union-find, Tarjan 1975) over `0..n`, with path halving. Each set's root is
//! its smallest element, so roots do not depend on the order of the unions.

/// Disjoint sets over `0..n`, each element alone at first.
#[derive(Debug, Clone)]
pub struct Sets {
    parent: Vec<u32>,
}

impl Sets {
    pub fn new(n: usize) -> Self {
        Self {
            parent: (0..n as u32).collect(),
        }
    }

    /// The root (smallest element) of `x`'s set.
    pub fn find(&mut self, mut x: u32) -> u32 {
        let p = &mut self.parent;
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }

    /// Join the sets of `a` and `b`; whether they were apart.
    pub fn union(&mut self, a: u32, b: u32) -> bool {
        let (a, b) = (self.find(a), self.find(b));
        if a != b {
            self.parent[a.max(b) as usize] = a.min(b);
        }
        a != b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_are_the_smallest_element_whatever_the_order() {
        let mut s = Sets::new(6);
        assert!(s.union(4, 2));
        assert!(s.union(5, 4));
        assert!(!s.union(2, 5));
        assert!(s.union(3, 1));
        assert_eq!(
            (0..6).map(|x| s.find(x)).collect::<Vec<_>>(),
            [0, 1, 2, 1, 2, 2]
        );
    }
}
