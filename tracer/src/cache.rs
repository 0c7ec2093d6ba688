//! Values built once and kept: for scene data derived from a scene, camera or
//! shading set-up (their GPU layouts), which both the scene and the code that
//! builds those layouts use.

use std::fmt;
use std::sync::{Arc, Mutex, OnceLock, PoisonError, Weak};

/// A value built on first use; `Debug` shows only whether it is built (GPU
/// words are long).
#[derive(Clone)]
pub struct BuiltOnce<T>(OnceLock<T>);

impl<T> Default for BuiltOnce<T> {
    fn default() -> Self {
        BuiltOnce(OnceLock::new())
    }
}

impl<T> BuiltOnce<T> {
    pub fn get_or_init(&self, build: impl FnOnce() -> T) -> &T {
        self.0.get_or_init(build)
    }
}

impl<T> fmt::Debug for BuiltOnce<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(if self.0.get().is_some() {
            "BuiltOnce(built)"
        } else {
            "BuiltOnce(not built)"
        })
    }
}

/// Values built from the `Arc<K>`s they describe, each kept while its `Arc`
/// lives: for fields that are replaced rather than changed in place
/// (`Arc::make_mut` on a shared value, or with this cache's weak reference
/// alive, moves the value to a new allocation, so a changed value is never
/// mistaken for the one a value was built from).
pub struct ArcKeyedCache<K, V> {
    entries: Mutex<Vec<(Weak<K>, V)>>,
}

impl<K, V: Clone> ArcKeyedCache<K, V> {
    pub fn get_or_build(&self, key: &Arc<K>, build: impl FnOnce(&K) -> V) -> V {
        match self.get_or_try_build(key, |k| Ok::<V, std::convert::Infallible>(build(k))) {
            Ok(value) => value,
            Err(never) => match never {},
        }
    }

    pub fn get_or_try_build<E>(
        &self,
        key: &Arc<K>,
        build: impl FnOnce(&K) -> Result<V, E>,
    ) -> Result<V, E> {
        // A panic while building leaves no entry behind; the lock itself is fine.
        let mut entries = self.entries.lock().unwrap_or_else(PoisonError::into_inner);
        entries.retain(|(built_from, _)| built_from.strong_count() > 0);
        // A weak reference keeps its allocation, so no other value gets its address.
        if let Some((_, value)) = entries
            .iter()
            .find(|(built_from, _)| std::ptr::eq(built_from.as_ptr(), Arc::as_ptr(key)))
        {
            return Ok(value.clone());
        }
        let value = build(key)?;
        entries.push((Arc::downgrade(key), value.clone()));
        Ok(value)
    }
}

impl<K, V> ArcKeyedCache<K, V> {
    pub const fn new() -> ArcKeyedCache<K, V> {
        ArcKeyedCache {
            entries: Mutex::new(Vec::new()),
        }
    }

    /// Forgets the values whose `Arc`s are gone.
    pub fn release_orphans(&self) {
        let mut entries = self.entries.lock().unwrap_or_else(PoisonError::into_inner);
        entries.retain(|(built_from, _)| built_from.strong_count() > 0);
    }
}

impl<K, V> Default for ArcKeyedCache<K, V> {
    fn default() -> Self {
        ArcKeyedCache::new()
    }
}

impl<K, V: Clone> Clone for ArcKeyedCache<K, V> {
    fn clone(&self) -> Self {
        let entries = self.entries.lock().unwrap_or_else(PoisonError::into_inner);
        ArcKeyedCache {
            entries: Mutex::new(entries.clone()),
        }
    }
}

impl<K, V> fmt::Debug for ArcKeyedCache<K, V> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let entries = self.entries.lock().unwrap_or_else(PoisonError::into_inner);
        write!(f, "ArcKeyedCache({} built)", entries.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_arc_keyed_cache_keeps_one_value_per_live_arc() {
        let cache = ArcKeyedCache::<u32, Arc<u32>>::new();
        let mut first = Arc::new(1);
        let second = Arc::new(2);
        let built = cache.get_or_build(&first, |k| Arc::new(k * 10));
        assert!(Arc::ptr_eq(
            &built,
            &cache.get_or_build(&first, |_| unreachable!())
        ));
        assert_eq!(*cache.get_or_build(&second, |k| Arc::new(k * 10)), 20);
        // A change through `make_mut` moves the value, so it is built anew.
        *Arc::make_mut(&mut first) = 3;
        assert_eq!(*cache.get_or_build(&first, |k| Arc::new(k * 10)), 30);
        drop(second);
        cache.release_orphans();
        assert_eq!(format!("{cache:?}"), "ArcKeyedCache(1 built)");
    }
}
