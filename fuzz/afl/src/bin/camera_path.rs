//! AFL++ target `camera_path`: `lemi_fuzz::fuzz_camera_path` under the 1 GiB allocation cap.

#[global_allocator]
static ALLOC: lemi_fuzz::CappedAlloc = lemi_fuzz::CappedAlloc;

fn main() {
    afl::fuzz!(|data: &[u8]| lemi_fuzz::fuzz_camera_path(data));
}
