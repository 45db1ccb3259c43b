//! The simulated Dynamixel bus: which servo answers which packet, in what order, and when.
//!
//! Owns the dispatch of every Protocol 2.0 instruction to the servos on the bus (unicast,
//! broadcast, secondary ID), the Status Return Level rules (ping is always answered; reads
//! at level ≥ 1; everything else only at level 2; broadcasts only for ping, sync read and
//! bulk read), the return delay before each status packet, and the mechanical coupling of
//! the bench: the driver servo turns the mechanism, and the torque-off follower servo's
//! shaft is placed by a [`FollowerLaw`] (the plant model) from the driver angle and time.
//!
//! Does not own byte framing ([`super::packet`]) nor the serial line ([`super::server`]).

use super::packet::{err, inst, Decoded, Packet, BROADCAST_ID};
use super::servo::{ResetKind, Role, Servo, PULSES_PER_REV};

/// The mechanism between the two servos: the follower joint angle for a driver angle.
pub trait FollowerLaw: Send {
    /// Follower rotation about its joint axis (rad, unwrapped) when the mechanism's driver
    /// is at `driver_angle` (rad, unwrapped, 0 at the start of the simulation) at time
    /// `t_s` (s since the simulator started).
    fn follower_angle(&mut self, driver_angle: f64, t_s: f64) -> f64;
}

impl<F: FnMut(f64, f64) -> f64 + Send> FollowerLaw for F {
    fn follower_angle(&mut self, driver_angle: f64, t_s: f64) -> f64 {
        self(driver_angle, t_s)
    }
}

/// Layout of the simulated bench.
#[derive(Debug, Clone, PartialEq)]
pub struct BusConfig {
    /// ID of the driver servo. Default 1 (factory ID).
    pub driver_id: u8,
    /// ID of the follower servo (torque off, used as an encoder); `None` for a driver-only
    /// bus. Default 2.
    pub follower_id: Option<u8>,
    /// Servo revolutions per mechanism driver revolution. Default 1 (direct drive).
    pub gear_ratio: f64,
    /// Follower servo's present position (pulses, physical frame) when the follower joint
    /// angle is 0: where the encoder happens to be mounted. Default 1024.
    pub follower_zero_pulses: f64,
    /// Driver servo's shaft position at power-on (pulses). Default 2048.
    pub driver_start_pulses: f64,
}

impl Default for BusConfig {
    fn default() -> Self {
        Self {
            driver_id: 1,
            follower_id: Some(2),
            gear_ratio: 1.0,
            follower_zero_pulses: 1024.0,
            driver_start_pulses: 2048.0,
        }
    }
}

/// One status packet to send, after waiting `delay_s` from the end of the previous one.
#[derive(Debug, Clone, PartialEq)]
pub struct Reply {
    /// Wait before sending (the servo's Return Delay Time).
    pub delay_s: f64,
    /// The encoded status packet.
    pub bytes: Vec<u8>,
}

/// Counters of what the bus has seen.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BusStats {
    /// Valid instruction packets handled.
    pub instructions: u64,
    /// Status packets produced.
    pub replies: u64,
    /// Packets that arrived with a bad CRC.
    pub crc_errors: u64,
}

/// The servos on the bus and the mechanism coupling them.
pub struct Bus {
    servos: Vec<Servo>,
    law: Box<dyn FollowerLaw>,
    config: BusConfig,
    driver_home_pulses: f64,
    now_s: f64,
    stats: BusStats,
}

impl std::fmt::Debug for Bus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bus")
            .field("servos", &self.servos)
            .field("config", &self.config)
            .field("now_s", &self.now_s)
            .finish()
    }
}

/// Status Return Level needed for an instruction to be answered.
fn required_level(instruction: u8) -> u8 {
    match instruction {
        inst::PING => 0,
        inst::READ | inst::SYNC_READ | inst::BULK_READ => 1,
        _ => 2,
    }
}

impl Bus {
    /// A bus with a factory-fresh driver (and follower) servo powered on at time 0.
    pub fn new(config: BusConfig, law: Box<dyn FollowerLaw>) -> Self {
        let mut servos = vec![Servo::new(
            config.driver_id,
            Role::Driver,
            config.driver_start_pulses,
            0.0,
        )];
        if let Some(fid) = config.follower_id {
            servos.push(Servo::new(
                fid,
                Role::Follower,
                config.follower_zero_pulses,
                0.0,
            ));
        }
        let driver_home_pulses = servos[0].shaft_pulses();
        let mut bus = Self {
            servos,
            law,
            config,
            driver_home_pulses,
            now_s: 0.0,
            stats: BusStats::default(),
        };
        bus.place_follower(0.0);
        bus
    }

    /// The servos, driver first.
    pub fn servos(&self) -> &[Servo] {
        &self.servos
    }

    /// Mutable access to a servo by its current ID (fault injection, tests).
    pub fn servo_mut(&mut self, id: u8) -> Option<&mut Servo> {
        self.servos.iter_mut().find(|s| s.id() == id)
    }

    /// The driver servo.
    pub fn driver(&self) -> &Servo {
        &self.servos[0]
    }

    /// The driver servo, mutable (fault injection).
    pub fn driver_mut(&mut self) -> &mut Servo {
        &mut self.servos[0]
    }

    /// The follower servo, if any.
    pub fn follower(&self) -> Option<&Servo> {
        self.servos.get(1)
    }

    /// What the bus has seen.
    pub fn stats(&self) -> BusStats {
        self.stats
    }

    /// Simulation time of the last advance (s).
    pub fn now_s(&self) -> f64 {
        self.now_s
    }

    /// The mechanism driver angle (rad, unwrapped, 0 at power-on).
    pub fn driver_angle(&self) -> f64 {
        (self.servos[0].shaft_pulses() - self.driver_home_pulses) / PULSES_PER_REV
            * std::f64::consts::TAU
            / self.config.gear_ratio
    }

    fn place_follower(&mut self, dt: f64) {
        if self.servos.len() < 2 {
            return;
        }
        let phi = self.driver_angle();
        let theta = self.law.follower_angle(phi, self.now_s);
        let pulses =
            self.config.follower_zero_pulses + theta / std::f64::consts::TAU * PULSES_PER_REV;
        self.servos[1].set_shaft_position(pulses, dt);
    }

    /// Advance the mechanics to `now_s` (s since start) in steps no longer than the
    /// servo's control step, so the follower tracks the driver closely.
    pub fn advance(&mut self, now_s: f64) {
        while self.now_s < now_s {
            let t = (self.now_s + super::servo::CONTROL_STEP_S).min(now_s);
            let dt = t - self.now_s;
            self.servos[0].advance(t);
            self.now_s = t;
            self.place_follower(dt);
            for s in self.servos.iter_mut().skip(1) {
                s.advance(t);
            }
        }
    }

    fn index_of(&self, id: u8) -> Option<usize> {
        self.servos.iter().position(|s| s.id() == id)
    }

    fn status(&mut self, idx: usize, error: u8, params: &[u8]) -> Reply {
        let s = &self.servos[idx];
        self.stats.replies += 1;
        Reply {
            delay_s: s.return_delay_s(),
            bytes: super::packet::encode_status(s.id(), error | s.alert(), params),
        }
    }

    /// Handle one decoded packet at time `now_s`; returns the status packets to send, in
    /// order.
    pub fn handle(&mut self, now_s: f64, decoded: &Decoded) -> Vec<Reply> {
        self.advance(now_s);
        match decoded {
            Decoded::CrcMismatch { id, instruction } => {
                self.stats.crc_errors += 1;
                match self.index_of(*id) {
                    Some(i)
                        if self.servos[i].status_return_level() >= required_level(*instruction) =>
                    {
                        vec![self.status(i, err::CRC, &[])]
                    }
                    _ => Vec::new(),
                }
            }
            Decoded::Packet(p) => {
                self.stats.instructions += 1;
                self.dispatch(now_s, p)
            }
        }
    }

    /// Indices of the servos a packet is addressed to, and whether it was addressed to
    /// them individually (only individually addressed servos answer).
    fn targets(&self, id: u8) -> (Vec<usize>, bool) {
        if id == BROADCAST_ID {
            return ((0..self.servos.len()).collect(), false);
        }
        if let Some(i) = self.index_of(id) {
            return (vec![i], true);
        }
        let shadow: Vec<usize> = (0..self.servos.len())
            .filter(|&i| self.servos[i].secondary_id() == Some(id))
            .collect();
        (shadow, false)
    }

    fn dispatch(&mut self, now_s: f64, p: &Packet) -> Vec<Reply> {
        let (targets, unicast) = self.targets(p.id);
        for &i in &targets {
            self.servos[i].note_instruction(now_s);
        }
        let mut replies = Vec::new();
        match p.instruction {
            inst::PING => {
                // Broadcast ping: every servo answers, in ID order.
                let mut order = targets.clone();
                order.sort_by_key(|&i| self.servos[i].id());
                if unicast || p.id == BROADCAST_ID {
                    for i in order {
                        let params = self.servos[i].ping_params();
                        replies.push(self.status(i, 0, &params));
                    }
                }
            }
            inst::SYNC_READ | inst::BULK_READ => {
                if p.id == BROADCAST_ID {
                    replies = self.group_read(p);
                }
            }
            inst::SYNC_WRITE | inst::BULK_WRITE => {
                if p.id == BROADCAST_ID {
                    self.group_write(p);
                }
            }
            _ => {
                for &i in &targets {
                    // The level in force when the packet arrived decides (a write of the
                    // level itself is answered under the old level).
                    let answers = unicast
                        && self.servos[i].status_return_level() >= required_level(p.instruction);
                    let result = self.execute(i, now_s, p);
                    if answers {
                        let (error, params) = match result {
                            Ok(params) => (0, params),
                            Err(e) => (e, Vec::new()),
                        };
                        replies.push(self.status(i, error, &params));
                    }
                    // After the reply is built (with the old ID), apply deferred effects.
                    self.after_reply(i, now_s, p, unicast);
                }
            }
        }
        replies
    }

    /// Execute a single-servo instruction; returns the status parameters or an error number.
    fn execute(&mut self, i: usize, _now_s: f64, p: &Packet) -> Result<Vec<u8>, u8> {
        let s = &mut self.servos[i];
        let b = &p.body;
        let addr_len = |b: &[u8]| {
            (
                u16::from_le_bytes([b[0], b[1]]),
                u16::from_le_bytes([b[2], b[3]]),
            )
        };
        match p.instruction {
            inst::READ => {
                if b.len() != 4 {
                    return Err(err::DATA_LENGTH);
                }
                let (a, n) = addr_len(b);
                s.read(a, n)
            }
            inst::WRITE => {
                if b.len() < 3 {
                    return Err(err::DATA_LENGTH);
                }
                s.write(u16::from_le_bytes([b[0], b[1]]), &b[2..])
                    .map(|()| Vec::new())
            }
            inst::REG_WRITE => {
                if b.len() < 3 {
                    return Err(err::DATA_LENGTH);
                }
                s.reg_write(u16::from_le_bytes([b[0], b[1]]), &b[2..])
                    .map(|()| Vec::new())
            }
            inst::ACTION => {
                if !b.is_empty() {
                    return Err(err::DATA_LENGTH);
                }
                s.action().map(|()| Vec::new())
            }
            inst::FACTORY_RESET => match b.as_slice() {
                [0xFF] if p.id == BROADCAST_ID => Err(err::RESULT_FAIL), // e-manual: ignored
                [0xFF] | [0x01] | [0x02] => Ok(Vec::new()),
                [_] => Err(err::DATA_RANGE),
                _ => Err(err::DATA_LENGTH),
            },
            inst::REBOOT => {
                if b.is_empty() {
                    Ok(Vec::new())
                } else {
                    Err(err::DATA_LENGTH)
                }
            }
            inst::CLEAR => match b.as_slice() {
                [0x01, 0x44, 0x58, 0x4C, 0x22] => s.clear_multi_turn().map(|()| Vec::new()),
                [0x01, ..] => Err(err::DATA_RANGE),
                _ => Err(err::RESULT_FAIL),
            },
            _ => Err(err::INSTRUCTION),
        }
    }

    /// Effects that happen after the status packet left: reboot and factory reset.
    fn after_reply(&mut self, i: usize, now_s: f64, p: &Packet, _unicast: bool) {
        match (p.instruction, p.body.as_slice()) {
            (inst::REBOOT, []) => self.servos[i].reboot(now_s),
            (inst::FACTORY_RESET, [opt]) => {
                let kind = match opt {
                    0xFF if p.id != BROADCAST_ID => ResetKind::All,
                    0x01 => ResetKind::KeepId,
                    0x02 => ResetKind::KeepIdAndBaud,
                    _ => return,
                };
                self.servos[i].factory_reset(kind, now_s);
            }
            _ => {}
        }
        if i == 0 && matches!(p.instruction, inst::REBOOT | inst::FACTORY_RESET) {
            // The driver's frame may have changed; keep the mechanism where it is.
            let phi = self.driver_angle();
            self.driver_home_pulses = self.servos[0].shaft_pulses()
                - phi * self.config.gear_ratio / std::f64::consts::TAU * PULSES_PER_REV;
        }
    }

    fn group_read(&mut self, p: &Packet) -> Vec<Reply> {
        let b = &p.body;
        let mut requests: Vec<(u8, u16, u16)> = Vec::new();
        if p.instruction == inst::SYNC_READ {
            if b.len() < 5 {
                return Vec::new();
            }
            let a = u16::from_le_bytes([b[0], b[1]]);
            let n = u16::from_le_bytes([b[2], b[3]]);
            requests.extend(b[4..].iter().map(|&id| (id, a, n)));
        } else {
            if b.is_empty() || b.len() % 5 != 0 {
                return Vec::new();
            }
            for c in b.chunks_exact(5) {
                // e-manual: each ID may appear only once in a bulk read.
                if requests.iter().any(|r| r.0 == c[0]) {
                    return Vec::new();
                }
                requests.push((
                    c[0],
                    u16::from_le_bytes([c[1], c[2]]),
                    u16::from_le_bytes([c[3], c[4]]),
                ));
            }
        }
        let mut replies = Vec::new();
        for (id, a, n) in requests {
            let Some(i) = self.index_of(id) else { continue };
            if self.servos[i].status_return_level() < 1 {
                continue;
            }
            let r = match self.servos[i].read(a, n) {
                Ok(data) => self.status(i, 0, &data),
                Err(e) => self.status(i, e, &[]),
            };
            replies.push(r);
        }
        replies
    }

    fn group_write(&mut self, p: &Packet) {
        let b = &p.body;
        if p.instruction == inst::SYNC_WRITE {
            if b.len() < 5 {
                return;
            }
            let a = u16::from_le_bytes([b[0], b[1]]);
            let n = usize::from(u16::from_le_bytes([b[2], b[3]]));
            if n == 0 || (b.len() - 4) % (n + 1) != 0 {
                return;
            }
            for c in b[4..].chunks_exact(n + 1) {
                if let Some(i) = self.index_of(c[0]) {
                    let _ = self.servos[i].write(a, &c[1..]);
                }
            }
        } else {
            let mut k = 0;
            while k + 5 <= b.len() {
                let id = b[k];
                let a = u16::from_le_bytes([b[k + 1], b[k + 2]]);
                let n = usize::from(u16::from_le_bytes([b[k + 3], b[k + 4]]));
                let Some(data) = b.get(k + 5..k + 5 + n) else {
                    return;
                };
                if let Some(i) = self.index_of(id) {
                    let _ = self.servos[i].write(a, data);
                }
                k += 5 + n;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::control_table::{addr, mode};
    use super::super::packet::{encode, Decoder};
    use super::*;

    fn bus() -> Bus {
        // Follower turns at half the driver's speed.
        Bus::new(
            BusConfig::default(),
            Box::new(|phi: f64, _t: f64| 0.5 * phi),
        )
    }

    fn run(bus: &mut Bus, now: f64, id: u8, instruction: u8, body: &[u8]) -> Vec<Packet> {
        let mut d = Decoder::new();
        d.push(&encode(id, instruction, body));
        let decoded = d.next_packet().expect("packet");
        let replies = bus.handle(now, &decoded);
        let mut out = Decoder::new();
        for r in &replies {
            out.push(&r.bytes);
        }
        let mut packets = Vec::new();
        while let Some(Decoded::Packet(p)) = out.next_packet() {
            packets.push(p);
        }
        packets
    }

    /// Guards ping: unicast and broadcast answers carry model 1060 and the firmware version,
    /// broadcast answers come in ID order, an absent ID stays silent.
    #[test]
    fn ping_unicast_and_broadcast() {
        let mut b = bus();
        let r = run(&mut b, 0.0, 1, inst::PING, &[]);
        assert_eq!(r.len(), 1);
        assert_eq!(
            r[0].body,
            vec![0, 0x24, 0x04, super::super::control_table::FIRMWARE_VERSION]
        );
        let r = run(&mut b, 0.0, BROADCAST_ID, inst::PING, &[]);
        assert_eq!(r.iter().map(|p| p.id).collect::<Vec<_>>(), vec![1, 2]);
        assert!(run(&mut b, 0.0, 7, inst::PING, &[]).is_empty());
    }

    /// Guards the Status Return Level rules: level 0 answers only ping, level 1 reads too,
    /// broadcast writes are never answered.
    #[test]
    fn status_return_level_gates_replies() {
        let mut b = bus();
        assert_eq!(
            run(
                &mut b,
                0.0,
                1,
                inst::WRITE,
                &[addr::STATUS_RETURN_LEVEL as u8, 0, 1]
            )
            .len(),
            1
        );
        assert!(run(&mut b, 0.0, 1, inst::WRITE, &[addr::LED as u8, 0, 1]).is_empty());
        assert_eq!(
            run(&mut b, 0.0, 1, inst::READ, &[addr::LED as u8, 0, 1, 0]).len(),
            1
        );
        run(
            &mut b,
            0.0,
            1,
            inst::WRITE,
            &[addr::STATUS_RETURN_LEVEL as u8, 0, 0],
        );
        assert!(run(&mut b, 0.0, 1, inst::READ, &[addr::LED as u8, 0, 1, 0]).is_empty());
        assert_eq!(run(&mut b, 0.0, 1, inst::PING, &[]).len(), 1);
        assert!(run(
            &mut b,
            0.0,
            BROADCAST_ID,
            inst::WRITE,
            &[addr::LED as u8, 0, 0]
        )
        .is_empty());
        assert_eq!(b.servos()[1].status_return_level(), 2);
    }

    /// Guards sync write + sync read across both servos and the follower coupling: the driver
    /// turns one revolution in velocity mode and the follower reports half a revolution.
    #[test]
    fn sync_read_sees_follower_track_driver() {
        let mut b = bus();
        run(
            &mut b,
            0.0,
            1,
            inst::WRITE,
            &[addr::OPERATING_MODE as u8, 0, mode::VELOCITY],
        );
        run(
            &mut b,
            0.0,
            1,
            inst::WRITE,
            &[addr::TORQUE_ENABLE as u8, 0, 1],
        );
        let start = run(
            &mut b,
            0.0,
            BROADCAST_ID,
            inst::SYNC_READ,
            &[132, 0, 4, 0, 1, 2],
        );
        let pos = |p: &Packet| i32::from_le_bytes([p.body[1], p.body[2], p.body[3], p.body[4]]);
        let (d0, f0) = (pos(&start[0]), pos(&start[1]));
        // 262 × 0.229 rpm = 60.0 rpm: one revolution per second.
        let mut body = vec![104, 0, 4, 0, 1];
        body.extend_from_slice(&262i32.to_le_bytes());
        run(&mut b, 0.0, BROADCAST_ID, inst::SYNC_WRITE, &body);
        let t = 60.0 / (262.0 * 0.229);
        let r = run(
            &mut b,
            t,
            BROADCAST_ID,
            inst::SYNC_READ,
            &[132, 0, 4, 0, 1, 2],
        );
        assert_eq!(r.iter().map(|p| p.id).collect::<Vec<_>>(), vec![1, 2]);
        assert!(
            (pos(&r[0]) - d0 - 4096).abs() <= 1,
            "driver {}",
            pos(&r[0]) - d0
        );
        assert!(
            (pos(&r[1]) - f0 - 2048).abs() <= 1,
            "follower {}",
            pos(&r[1]) - f0
        );
        // Bulk read: different items from each servo.
        let r = run(
            &mut b,
            t,
            BROADCAST_ID,
            inst::BULK_READ,
            &[1, 64, 0, 1, 0, 2, 0, 0, 2, 0],
        );
        assert_eq!(r[0].body, vec![0, 1]);
        assert_eq!(r[1].body, vec![0, 0x24, 0x04]);
    }

    /// Guards error replies: undefined instruction, read past the table, Action without a
    /// registered write, and the CRC error reply to a damaged unicast packet.
    #[test]
    fn error_replies_carry_e_manual_numbers() {
        let mut b = bus();
        assert_eq!(
            run(&mut b, 0.0, 1, 0x30, &[]).first().map(|p| p.body[0]),
            Some(err::INSTRUCTION)
        );
        assert_eq!(
            run(&mut b, 0.0, 1, inst::READ, &[0x90, 0x02, 10, 0])
                .first()
                .map(|p| p.body[0]),
            Some(err::ACCESS)
        );
        assert_eq!(
            run(&mut b, 0.0, 1, inst::ACTION, &[])
                .first()
                .map(|p| p.body[0]),
            Some(err::INSTRUCTION)
        );
        let replies = b.handle(
            0.0,
            &Decoded::CrcMismatch {
                id: 2,
                instruction: inst::READ,
            },
        );
        let mut d = Decoder::new();
        d.push(&replies[0].bytes);
        match d.next_packet() {
            Some(Decoded::Packet(p)) => assert_eq!((p.id, p.body[0]), (2, err::CRC)),
            other => panic!("{other:?}"),
        }
    }

    /// Guards reboot and factory reset: the reply uses the old state, then RAM (and for a
    /// reset, EEPROM) returns to defaults; a broadcast reset-all is refused.
    #[test]
    fn reboot_and_factory_reset() {
        let mut b = bus();
        run(&mut b, 0.0, 1, inst::WRITE, &[addr::LED as u8, 0, 1]);
        run(
            &mut b,
            0.0,
            1,
            inst::WRITE,
            &[addr::RETURN_DELAY_TIME as u8, 0, 10],
        );
        assert_eq!(run(&mut b, 0.0, 1, inst::REBOOT, &[]).len(), 1);
        assert_eq!(
            run(&mut b, 0.0, 1, inst::READ, &[addr::LED as u8, 0, 1, 0])[0].body,
            vec![0, 0]
        );
        assert_eq!(
            run(
                &mut b,
                0.0,
                1,
                inst::READ,
                &[addr::RETURN_DELAY_TIME as u8, 0, 1, 0]
            )[0]
            .body,
            vec![0, 10],
            "EEPROM survives reboot"
        );
        run(&mut b, 0.0, 2, inst::WRITE, &[addr::ID as u8, 0, 9]);
        assert!(run(&mut b, 0.0, BROADCAST_ID, inst::FACTORY_RESET, &[0xFF]).is_empty());
        assert_eq!(b.follower().unwrap().id(), 9);
        let r = run(&mut b, 0.0, 9, inst::FACTORY_RESET, &[0x01]);
        assert_eq!(r[0].id, 9);
        assert_eq!(b.follower().unwrap().id(), 9, "0x01 keeps the ID");
        run(&mut b, 0.0, 1, inst::FACTORY_RESET, &[0xFF]);
        assert_eq!(
            run(
                &mut b,
                0.0,
                1,
                inst::READ,
                &[addr::RETURN_DELAY_TIME as u8, 0, 1, 0]
            )[0]
            .body,
            vec![0, 250]
        );
    }
}
