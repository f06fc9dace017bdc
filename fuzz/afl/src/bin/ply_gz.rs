//! AFL++ target `ply_gz`: `lemi_fuzz::fuzz_ply_gz` under the 1 GiB allocation cap.

#[global_allocator]
static ALLOC: lemi_fuzz::CappedAlloc = lemi_fuzz::CappedAlloc;

fn main() {
    afl::fuzz!(|data: &[u8]| lemi_fuzz::fuzz_ply_gz(data));
}
