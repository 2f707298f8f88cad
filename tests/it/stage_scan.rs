//! The stage as a whole scan uses it: the real `surfscan scan` binary against the simulated
//! GRBL board (just powered up, in Alarm), counting what the board was asked to do.

use crate::common::*;

/// One homing cycle per scan, whether it is asked for (`home-on-start`) or needed because the
/// board powered up without a reference: each `$H` costs seconds on a real stage.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scan_homes_the_stage_exactly_once() {
    for home_on_start in [true, false] {
        let rig = Rig::start(RigOptions {
            lines: 6,
            ..RigOptions::default()
        })
        .await;
        let cfg = rig.config("out");
        if !home_on_start {
            let text = std::fs::read_to_string(&cfg).unwrap();
            std::fs::write(
                &cfg,
                edited(&text, "home-on-start = true", "home-on-start = false"),
            )
            .unwrap();
        }
        let o = run_scan(&cfg, &[]).await;
        assert!(o.status.success(), "{}", describe(&o));
        assert_eq!(
            rig.stage.homing_cycles(),
            1,
            "home-on-start = {home_on_start}: {}",
            describe(&o)
        );
        rig.shutdown().await;
    }
}
