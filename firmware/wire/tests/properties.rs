//! Property tests of the codec and framing: every message survives encode → decode, any
//! byte sequence is safe to feed to the decoder, and the decoder resynchronizes at the
//! first frame boundary after garbage.

use mpc_wire::{
    encode_frame, AckCode, BoardName, Capabilities, Command, Config, Decoder, DeviceInfo, Event,
    EventKind, Frame, FrameError, MotionMode, Report, Sample, SampleBatch, SampleFlags, SensorSet,
    Status, StatusFlags, MAX_BATCH, MAX_FRAME_LEN,
};
use proptest::prelude::*;

fn sensors() -> impl Strategy<Value = SensorSet> {
    (0u8..16).prop_map(SensorSet)
}

fn config() -> impl Strategy<Value = Config> {
    (
        (any::<u16>(), any::<u16>(), any::<u16>(), any::<u16>()),
        (any::<u32>(), any::<u32>(), any::<bool>(), any::<u16>()),
        (sensors(), any::<u8>(), any::<u16>(), any::<u8>()),
    )
        .prop_map(|((a, b, c, d), (e, f, g, h), (i, j, k, l))| Config {
            steps_per_rev: a,
            microsteps: b,
            gear_motor: c,
            gear_output: d,
            max_speed_mdeg_s: e,
            max_accel_mdeg_s2: f,
            reverse: g,
            sample_rate_hz: h,
            sensors: i,
            batch_len: j,
            watchdog_ms: k,
            imu_every: l,
        })
}

fn command() -> impl Strategy<Value = Command> {
    prop_oneof![
        any::<u16>().prop_map(|v| Command::Hello {
            protocol_version: v
        }),
        config().prop_map(Command::Configure),
        any::<bool>().prop_map(Command::SetMotorEnabled),
        any::<i32>().prop_map(|v| Command::RunSpeed { speed_mdeg_s: v }),
        any::<i32>().prop_map(|v| Command::MoveTo { angle_mdeg: v }),
        any::<i32>().prop_map(|v| Command::MoveBy { delta_mdeg: v }),
        Just(Command::Stop),
        Just(Command::EmergencyStop),
        Just(Command::ClearEmergencyStop),
        Just(Command::Zero),
        Just(Command::Home),
        Just(Command::Heartbeat),
        Just(Command::QueryStatus),
        Just(Command::StartStream),
        Just(Command::StopStream),
    ]
}

fn sample() -> impl Strategy<Value = Sample> {
    (
        any::<u32>(),
        any::<i32>(),
        any::<u8>(),
        any::<u16>(),
        any::<u16>(),
        any::<i32>(),
        any::<[i16; 4]>(),
    )
        .prop_map(|(t, p, f, a, b, q, quat)| Sample {
            timestamp_us: t,
            position: p,
            flags: SampleFlags(f),
            encoder_a: a,
            encoder_b: b,
            quadrature: q,
            quaternion: quat,
        })
}

fn ack_code() -> impl Strategy<Value = AckCode> {
    prop::sample::select(vec![
        AckCode::Ok,
        AckCode::VersionMismatch,
        AckCode::InvalidConfig,
        AckCode::NotConfigured,
        AckCode::MotorDisabled,
        AckCode::EStopLatched,
        AckCode::OutOfRange,
        AckCode::Busy,
        AckCode::Unsupported,
    ])
}

fn report() -> impl Strategy<Value = Report> {
    prop_oneof![
        (
            any::<u16>(),
            any::<u16>(),
            any::<[u8; 3]>(),
            "[a-z0-9-]{0,16}",
            sensors(),
            (
                any::<u32>(),
                any::<u16>(),
                any::<u16>(),
                any::<u8>(),
                any::<u32>()
            )
        )
            .prop_map(|(ack, pv, fw, name, s, (msr, sr, ir, mb, clk))| {
                Report::Hello(DeviceInfo {
                    ack,
                    protocol_version: pv,
                    firmware_version: fw,
                    board: BoardName::new(&name).unwrap(),
                    capabilities: Capabilities {
                        sensors: s,
                        max_step_rate_hz: msr,
                        max_sample_rate_hz: sr,
                        imu_rate_hz: ir,
                        max_batch: mb,
                    },
                    clock_hz: clk,
                })
            }),
        (any::<u16>(), ack_code()).prop_map(|(ack, code)| Report::Ack { ack, code }),
        (
            any::<u16>(),
            any::<u32>(),
            any::<(i32, i32, i32)>(),
            0u8..4,
            0u16..(1 << 9),
            any::<(u32, u32)>()
        )
            .prop_map(|(ack, t, (p, v, g), m, f, (rx, dr))| {
                Report::Status(Status {
                    ack,
                    timestamp_us: t,
                    position: p,
                    speed: v,
                    target: g,
                    mode: [
                        MotionMode::Idle,
                        MotionMode::Run,
                        MotionMode::Move,
                        MotionMode::Stopping,
                    ][m as usize],
                    flags: StatusFlags(f),
                    rx_errors: rx,
                    samples_dropped: dr,
                })
            }),
        (sensors(), prop::collection::vec(sample(), 0..=MAX_BATCH)).prop_map(|(f, ss)| {
            let mut b = SampleBatch::new(f);
            for s in ss {
                b.push(s).unwrap();
            }
            Report::Samples(b)
        }),
        (1u8..=6, any::<u8>(), any::<u32>(), any::<i32>()).prop_map(|(k, d, t, p)| {
            Report::Event(Event {
                kind: [
                    EventKind::Boot,
                    EventKind::MoveDone,
                    EventKind::Stopped,
                    EventKind::EmergencyStop,
                    EventKind::WatchdogExpired,
                    EventKind::SensorFault,
                ][k as usize - 1],
                detail: d,
                timestamp_us: t,
                position: p,
            })
        }),
    ]
}

fn encode<M: mpc_wire::Message>(seq: u16, m: &M) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = encode_frame(seq, m, &mut buf).unwrap();
    buf[..n].to_vec()
}

fn decode_all<M: mpc_wire::Message>(bytes: &[u8]) -> Vec<Result<Frame<M>, FrameError>> {
    let mut out = Vec::new();
    Decoder::<M>::new().feed(bytes, |r| out.push(r));
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// Guards encode → decode identity for every command, whatever its field values.
    #[test]
    fn command_roundtrip(seq in any::<u16>(), cmd in command()) {
        let bytes = encode(seq, &cmd);
        prop_assert!(bytes.len() <= MAX_FRAME_LEN);
        prop_assert_eq!(decode_all::<Command>(&bytes), vec![Ok(Frame { seq, msg: cmd })]);
    }

    /// Guards encode → decode identity for every report, including full sample batches.
    #[test]
    fn report_roundtrip(seq in any::<u16>(), rep in report()) {
        let bytes = encode(seq, &rep);
        prop_assert!(bytes.len() <= MAX_FRAME_LEN);
        prop_assert_eq!(decode_all::<Report>(&bytes), vec![Ok(Frame { seq, msg: rep })]);
    }

    /// Guards that how bytes are split into reads does not change what is decoded.
    #[test]
    fn chunking_does_not_matter(reps in prop::collection::vec(report(), 1..6), cut in any::<prop::sample::Index>()) {
        let mut stream = Vec::new();
        for (i, r) in reps.iter().enumerate() {
            stream.extend(encode(i as u16, r));
        }
        let at = cut.index(stream.len());
        let mut d = Decoder::<Report>::new();
        let mut got = Vec::new();
        d.feed(&stream[..at], |r| got.push(r));
        d.feed(&stream[at..], |r| got.push(r));
        prop_assert_eq!(got, decode_all::<Report>(&stream));
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(5000))]

    /// Guards that arbitrary bytes never panic either decoder, and that every result is
    /// produced by a delimiter (no frame without its 0x00).
    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..3000)) {
        let zeros = bytes.iter().filter(|&&b| b == 0).count();
        let c = decode_all::<Command>(&bytes);
        let r = decode_all::<Report>(&bytes);
        prop_assert!(c.len() <= zeros && r.len() <= zeros);
    }

    /// Guards resynchronization: after any garbage, a 0x00 and then a valid frame, the valid
    /// frame is the last thing decoded, intact.
    #[test]
    fn decoder_resynchronizes_after_garbage(
        garbage in prop::collection::vec(any::<u8>(), 0..2000),
        seq in any::<u16>(),
        rep in report(),
    ) {
        let mut stream = garbage;
        stream.push(0);
        stream.extend(encode(seq, &rep));
        let got = decode_all::<Report>(&stream);
        prop_assert_eq!(got.last(), Some(&Ok(Frame { seq, msg: rep })));
    }

    /// Guards that flipping bits in a frame is detected (CRC) rather than decoded as a
    /// different message, and that the following frame still arrives.
    #[test]
    fn corruption_is_detected(cmd in command(), pos in any::<prop::sample::Index>(), mask in 1u8..=255) {
        let mut a = encode(1, &cmd);
        let i = pos.index(a.len() - 1);
        a[i] ^= mask;
        let b = encode(2, &Command::Heartbeat);
        let mut stream = a;
        stream.extend(&b);
        let got = decode_all::<Command>(&stream);
        prop_assert!(!got.iter().any(|r| matches!(r, Ok(f) if f.seq == 1)), "{:?}", got);
        prop_assert_eq!(got.last(), Some(&Ok(Frame { seq: 2, msg: Command::Heartbeat })));
    }
}
