//! Items grouped by equal keys through a radix sort: the way data-parallel
//! libraries find duplicates, used where a hash map of keys was most of a
//! scene's set-up (an isosurface's welding, a VTK grid's shared faces).

use rayon::prelude::*;

/// An item's key beside its index; sorted by the key alone.
#[derive(Clone, Copy)]
pub(crate) struct Keyed<K> {
    pub key: K,
    pub index: u32,
}

impl<K: rdst::RadixKey> rdst::RadixKey for Keyed<K> {
    const LEVELS: usize = K::LEVELS;

    #[inline]
    fn get_level(&self, level: usize) -> u8 {
        self.key.get_level(level)
    }
}

/// Sorts `items` by key and calls `run` on every run of equal keys, on every
/// core. A run's items come in no particular order (the sort is unstable),
/// so what `run` decides must not depend on it.
pub(crate) fn for_each_run_of_equal_keys<K>(
    mut items: Vec<Keyed<K>>,
    run: impl Fn(&[Keyed<K>]) + Sync,
) where
    K: rdst::RadixKey + PartialEq + Copy + Send + Sync,
{
    rdst::RadixSort::radix_sort_unstable(&mut items);
    items.par_chunk_by(|a, b| a.key == b.key).for_each(&run);
}
