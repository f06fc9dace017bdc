//! AFL++ target `ktx2`: `lemi_fuzz::fuzz_ktx2` under the 1 GiB allocation cap.

#[global_allocator]
static ALLOC: lemi_fuzz::CappedAlloc = lemi_fuzz::CappedAlloc;

fn main() {
    afl::fuzz!(|data: &[u8]| lemi_fuzz::fuzz_ktx2(data));
}
