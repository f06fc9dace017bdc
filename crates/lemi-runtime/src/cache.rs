//! The cell cache: least recently used cells are evicted once the cached bytes exceed a budget,
//! except the cells the caller keeps (the current cell is never evicted).
//!
//! This work is based on GI 2002 sec. 3 and sec. 7: the compressed impostors are small enough
//! that "textures for several view cells \[can\] be held in texture memory simultaneously, allowing
//! prefetching"; the budget says how many. The cache is generic over what it holds (the streamer
//! keeps cells decoded on the CPU, uploading, or uploaded on the GPU, with their current sizes)
//! and counts what it evicts.
//!
//! Recency is a counter: [`Cache::touch`] gives an entry the next tick, so a caller that touches
//! its wanted cells every frame, least wanted first, makes the eviction order "not wanted this
//! frame (oldest first), then least wanted".

use std::borrow::Borrow;
use std::collections::HashMap;
use std::hash::Hash;

struct Entry<T> {
    value: T,
    bytes: u64,
    last_used: u64,
}

/// An evicted entry.
#[derive(Debug)]
pub struct Evicted<K, T> {
    pub id: K,
    pub value: T,
    pub bytes: u64,
}

/// A byte-bounded LRU cache keyed by `K` (the streamer's key is the cell id).
pub struct Cache<K, T> {
    budget: u64,
    entries: HashMap<K, Entry<T>>,
    tick: u64,
    total: u64,
    evictions: u64,
}

impl<K: Clone + Eq + Hash, T> Cache<K, T> {
    pub fn new(budget_bytes: u64) -> Cache<K, T> {
        Cache {
            budget: budget_bytes,
            entries: HashMap::new(),
            tick: 0,
            total: 0,
            evictions: 0,
        }
    }

    pub fn budget(&self) -> u64 {
        self.budget
    }

    /// Bytes of all entries.
    pub fn total_bytes(&self) -> u64 {
        self.total
    }

    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Entries evicted so far by [`Cache::evict_to_budget`].
    pub fn evictions(&self) -> u64 {
        self.evictions
    }

    pub fn contains<Q: Hash + Eq + ?Sized>(&self, id: &Q) -> bool
    where
        K: Borrow<Q>,
    {
        self.entries.contains_key(id)
    }

    pub fn get<Q: Hash + Eq + ?Sized>(&self, id: &Q) -> Option<&T>
    where
        K: Borrow<Q>,
    {
        self.entries.get(id).map(|e| &e.value)
    }

    pub fn get_mut<Q: Hash + Eq + ?Sized>(&mut self, id: &Q) -> Option<&mut T>
    where
        K: Borrow<Q>,
    {
        self.entries.get_mut(id).map(|e| &mut e.value)
    }

    /// Bytes of one entry.
    pub fn bytes<Q: Hash + Eq + ?Sized>(&self, id: &Q) -> Option<u64>
    where
        K: Borrow<Q>,
    {
        self.entries.get(id).map(|e| e.bytes)
    }

    /// Inserts (or replaces) `id` as the most recently used entry; returns the replaced value.
    /// Does not evict: call [`Cache::evict_to_budget`].
    pub fn insert(&mut self, id: K, value: T, bytes: u64) -> Option<T> {
        self.tick += 1;
        let old = self.entries.insert(
            id,
            Entry {
                value,
                bytes,
                last_used: self.tick,
            },
        );
        self.total += bytes;
        old.map(|e| {
            self.total -= e.bytes;
            e.value
        })
    }

    /// Changes the recorded size of `id` (its value changed state, e.g. uploaded to the GPU).
    pub fn set_bytes<Q: Hash + Eq + ?Sized>(&mut self, id: &Q, bytes: u64)
    where
        K: Borrow<Q>,
    {
        if let Some(e) = self.entries.get_mut(id) {
            self.total = self.total - e.bytes + bytes;
            e.bytes = bytes;
        }
    }

    /// Makes `id` the most recently used entry; false if absent.
    pub fn touch<Q: Hash + Eq + ?Sized>(&mut self, id: &Q) -> bool
    where
        K: Borrow<Q>,
    {
        self.tick += 1;
        match self.entries.get_mut(id) {
            Some(e) => {
                e.last_used = self.tick;
                true
            }
            None => false,
        }
    }

    pub fn remove<Q: Hash + Eq + ?Sized>(&mut self, id: &Q) -> Option<T>
    where
        K: Borrow<Q>,
    {
        self.entries.remove(id).map(|e| {
            self.total -= e.bytes;
            e.value
        })
    }

    /// Ids from least to most recently used.
    pub fn lru_order(&self) -> Vec<&K> {
        let mut v: Vec<(&K, u64)> = self.entries.iter().map(|(k, e)| (k, e.last_used)).collect();
        v.sort_by_key(|&(_, t)| t);
        v.into_iter().map(|(k, _)| k).collect()
    }

    /// Evicts least recently used entries, never one named in `keep`, until the total is within
    /// the budget or only kept entries remain (a kept cell larger than the budget stays: the
    /// current cell is never evicted). Returns the evicted entries, least recently used first.
    pub fn evict_to_budget<Q: Eq + ?Sized>(&mut self, keep: &[&Q]) -> Vec<Evicted<K, T>>
    where
        K: Borrow<Q>,
    {
        let mut out = Vec::new();
        while self.total > self.budget {
            let victim = self
                .entries
                .iter()
                .filter(|(k, _)| !keep.iter().any(|q| (*k).borrow() == *q))
                .min_by_key(|(_, e)| e.last_used)
                .map(|(k, _)| k.clone());
            let Some(id) = victim else { break };
            if let Some(e) = self.entries.remove::<K>(&id) {
                self.total -= e.bytes;
                self.evictions += 1;
                out.push(Evicted {
                    id,
                    value: e.value,
                    bytes: e.bytes,
                });
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ids<T>(e: &[Evicted<String, T>]) -> Vec<&str> {
        e.iter().map(|e| e.id.as_str()).collect()
    }

    #[test]
    fn evicts_least_recently_used_within_budget() {
        let mut c: Cache<String, i32> = Cache::new(100);
        c.insert("a".into(), 1, 40);
        c.insert("b".into(), 2, 40);
        assert!(c.evict_to_budget::<str>(&[]).is_empty());
        c.insert("c".into(), 3, 40);
        assert_eq!(c.total_bytes(), 120);
        c.touch("a"); // b is now the least recently used
        let e = c.evict_to_budget::<str>(&[]);
        assert_eq!(ids(&e), vec!["b"]);
        assert_eq!(e[0].value, 2);
        assert_eq!(c.total_bytes(), 80);
        assert_eq!(c.lru_order(), vec!["c", "a"]);
        assert_eq!(c.evictions(), 1);
        // growing an entry evicts others, never a kept one
        c.set_bytes("c", 90);
        let e = c.evict_to_budget(&["c"]);
        assert_eq!(ids(&e), vec!["a"]);
        assert_eq!(c.total_bytes(), 90);
        // a kept entry over budget stays
        c.set_bytes("c", 500);
        assert!(c.evict_to_budget(&["c"]).is_empty());
        assert_eq!(c.get("c"), Some(&3));
        assert_eq!(ids(&c.evict_to_budget::<str>(&[])), vec!["c"]);
        assert!(c.is_empty());
        assert_eq!(c.total_bytes(), 0);
        assert_eq!(c.evictions(), 3);
    }

    #[test]
    fn replace_and_remove_keep_the_byte_count() {
        let mut c: Cache<String, &str> = Cache::new(10);
        assert_eq!(c.insert("a".into(), "x", 4), None);
        assert_eq!(c.insert("a".into(), "y", 6), Some("x"));
        assert_eq!(c.total_bytes(), 6);
        assert_eq!(c.bytes("a"), Some(6));
        assert!(!c.touch("zz"));
        if let Some(v) = c.get_mut("a") {
            *v = "z";
        }
        assert_eq!(c.remove("a"), Some("z"));
        assert_eq!(c.total_bytes(), 0);
        assert_eq!(c.len(), 0);
        assert!(!c.contains("a"));
    }
}
