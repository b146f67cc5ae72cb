//! TDMS raw data laid out channel after channel and interleaved (what DAQ
//! loggers write) read as the same channels, with `wf_increment` as the time
//! base: the layout the served TDMS crates mis-read.

use hammer_fuzz::targets::import::tdms;
use hammer_trace::import::tdms::read;

#[test]
fn interleaved_and_contiguous_tdms_give_the_same_channels() {
    let a: Vec<f64> = (0..50).map(|i| i as f64 * 1.5).collect();
    let b: Vec<f64> = (0..50).map(|i| -(i as f64)).collect();
    let chans = [("p_rear_pa", a.clone()), ("accel_mps2", b.clone())];
    for interleaved in [false, true] {
        let got = read(&tdms(&chans, interleaved), None).unwrap();
        assert_eq!(got.len(), 2, "interleaved {interleaved}");
        let by = |n: &str| got.iter().find(|c| c.name == n).unwrap();
        assert_eq!(by("bench/p_rear_pa").values, a, "interleaved {interleaved}");
        assert_eq!(by("bench/accel_mps2").values, b, "interleaved {interleaved}");
        assert_eq!(by("bench/p_rear_pa").increment_s, Some(1e-5));
    }
    // A group filter that matches nothing says so.
    let e = read(&tdms(&chans, true), Some("other")).unwrap_err();
    assert!(e.contains("no numeric channel in group `other`"), "{e}");
}
