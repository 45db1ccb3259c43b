//! Golden frames in `data/wire/`: the bytes this crate writes must equal the stored files,
//! and the stored files must decode to the listed messages. Set `MPC_WIRE_BLESS=1` to
//! (re)write the files after a deliberate protocol change (with a new protocol version).

use std::path::PathBuf;

use mpc_wire::golden::cases;

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/wire")
}

/// Guards byte-stability of the protocol: encoding every golden message reproduces the
/// stored frame exactly, and decoding the stored frame gives the message back.
#[test]
fn golden_frames_encode_and_decode_exactly() {
    let bless = std::env::var_os("MPC_WIRE_BLESS").is_some();
    for case in cases() {
        let path = dir().join(format!("{}.bin", case.name));
        let ours = case.encode();
        if bless {
            std::fs::write(&path, &ours).unwrap();
        }
        let stored = std::fs::read(&path)
            .unwrap_or_else(|e| panic!("{}: {e} (run with MPC_WIRE_BLESS=1 once)", path.display()));
        assert_eq!(ours, stored, "{} differs from the stored frame", case.name);
        case.matches(&stored).unwrap();
    }
}

/// Guards that every golden file is listed (no stale file without a test).
#[test]
fn every_golden_file_is_a_known_case() {
    let names: Vec<String> = cases().iter().map(|c| format!("{}.bin", c.name)).collect();
    for entry in std::fs::read_dir(dir()).unwrap() {
        let name = entry.unwrap().file_name().into_string().unwrap();
        if name.ends_with(".bin") {
            assert!(
                names.contains(&name),
                "data/wire/{name} is not a golden case"
            );
        }
    }
}

/// Guards resynchronization as a host joining a running stream sees it: garbage without a
/// delimiter (here a lone 0xFF) spoils only the frame it runs into; every frame after the
/// next 0x00 decodes, also with delimiter-terminated garbage between frames.
#[test]
fn golden_stream_with_garbage_between_frames_resynchronizes() {
    let mut stream = vec![0x13, 0x37, 0x00, 0xFF];
    let reports: Vec<_> = cases()
        .into_iter()
        .filter(|c| matches!(c.msg, mpc_wire::golden::GoldenMessage::Report(_)))
        .collect();
    for c in &reports {
        stream.extend(std::fs::read(dir().join(format!("{}.bin", c.name))).unwrap());
        stream.extend([0x42, 0x99, 0x00]);
    }
    let mut good = Vec::new();
    mpc_wire::Decoder::<mpc_wire::Report>::new().feed(&stream, |r| {
        if let Ok(f) = r {
            good.push(f.seq);
        }
    });
    // The first frame is swallowed by the 0xFF (a COBS block announcing 254 bytes).
    let want: Vec<u16> = reports[1..].iter().map(|c| c.seq).collect();
    assert_eq!(good, want);
}
