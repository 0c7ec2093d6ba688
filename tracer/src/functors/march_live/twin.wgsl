// The WGSL twin of `marchLive` (mod.rs beside this file): t <= tEnd, false
// where either is NaN (a comparison with NaN is false in WGSL too, where the
// compiler keeps NaN; marches never hold NaN, see volumeEntry).

fn $FUNCTION(index: u32, march: March) -> bool {
    return march.t <= march.tEnd;
}
