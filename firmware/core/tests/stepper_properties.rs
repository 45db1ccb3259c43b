//! Property tests of the step generator under random limits and random command sequences
//! at random times: the maximum step rate is never exceeded, the direction changes only at
//! rest, and a final move always ends exactly on its target at rest.

use mpc_firmware_core::stepper::{Limits, StepGenerator};
use proptest::prelude::*;

#[derive(Debug, Clone)]
enum Cmd {
    MoveTo(i64),
    Run(i64),
    Stop,
}

fn cmd() -> impl Strategy<Value = Cmd> {
    prop_oneof![
        (-3000i64..3000).prop_map(Cmd::MoveTo),
        (-30_000i64..30_000).prop_map(Cmd::Run),
        Just(Cmd::Stop),
    ]
}

/// Take every step due up to `until`, checking the invariants on each.
fn advance(g: &mut StepGenerator, until: u64, last: &mut Option<u64>, min_interval: u64) {
    while let Some(t) = g.next_step_us().filter(|&t| t <= until) {
        let n_before = g.ramp_index();
        let ev = g.pop_due(t).expect("a due step");
        if ev.dir_changed {
            assert_eq!(n_before, 0, "direction changed at ramp index {n_before}");
        }
        if let Some(prev) = *last {
            assert!(ev.at_us >= prev, "steps out of order");
            assert!(
                ev.at_us - prev + 1 >= min_interval,
                "interval {} µs below {} µs",
                ev.at_us - prev,
                min_interval
            );
        }
        *last = Some(ev.at_us);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Guards the generator's invariants under arbitrary command sequences.
    #[test]
    fn random_commands_keep_invariants_and_final_move_is_exact(
        max_speed in 200u32..20_000,
        accel in 500u32..100_000,
        cmds in prop::collection::vec((cmd(), 0u64..300_000), 1..8),
        target in -3000i64..3000,
    ) {
        let limits = Limits { max_speed, accel };
        prop_assume!(limits.validate().is_ok());
        let min_interval = 1_000_000 / max_speed as u64;
        let mut g = StepGenerator::new(limits);
        let mut now = 0u64;
        let mut last = None;
        for (c, dt) in cmds {
            match c {
                Cmd::MoveTo(p) => g.move_to(p, now),
                Cmd::Run(s) => g.run(s, now),
                Cmd::Stop => g.stop(now),
            }
            now += dt;
            advance(&mut g, now, &mut last, min_interval);
        }
        g.move_to(target, now);
        advance(&mut g, u64::MAX, &mut last, min_interval);
        prop_assert!(g.is_idle());
        prop_assert_eq!(g.position(), target);
        prop_assert_eq!(g.ramp_index(), 0);
        prop_assert_eq!(g.speed(), 0);
    }
}
