//! One simulated XL430-class servo: its control table and the behaviour behind it.
//!
//! Owns: reads and writes with the e-manual's error rules (reserved and read-only addresses,
//! EEPROM lock while torque is on, partial items, value ranges and limits, indirect
//! addressing), Reg Write/Action, reboot, factory reset and Clear, the bus watchdog, the
//! operating modes (velocity, position, extended position, PWM) with velocity-based
//! profiles, and the live items (present position/velocity, trajectories, moving status,
//! realtime tick). Hardware errors can be injected and obey the Shutdown mask.
//!
//! Does not own: packet framing ([`super::packet`]), which servo answers which packet and
//! in what order ([`super::bus`]), or where a torque-off follower's shaft is — the bus sets
//! it from the plant model through [`Servo::set_shaft_position`].
//!
//! Positions are kept in *pulses* (4096 per revolution) as `f64` in the servo's own frame
//! (Drive Mode bit 0 reverses it); the reported Present Position adds the Homing Offset.

use std::sync::OnceLock;

use super::control_table::{
    addr, mode, Access, Area, Item, Layout, Range, EXTENDED_POSITION_LIMIT, TABLE_SIZE,
};
use super::packet::err;

/// Encoder pulses per revolution of the output shaft.
pub const PULSES_PER_REV: f64 = 4096.0;

/// Velocity unit of Goal/Present Velocity, Profile Velocity and Velocity Limit: 0.229 rpm.
pub const VELOCITY_UNIT_RPM: f64 = 0.229;

/// Profile Acceleration unit: 214.577 rev/min².
pub const ACCELERATION_UNIT_RPM_PER_MIN: f64 = 214.577;

/// No-load speed used to turn Goal PWM into a speed in PWM mode. Default 61 rpm: the
/// XL430-W250's no-load speed at 12 V (e-manual specifications).
pub const NO_LOAD_SPEED_RPM: f64 = 61.0;

/// Full-scale PWM value (PWM Limit maximum, 100 %).
pub const PWM_FULL_SCALE: f64 = 885.0;

/// Integration step of the simulated motion controller. Default 1 ms: fine enough that a
/// trapezoidal profile at the XL430's top speed lands within a pulse of its goal.
pub const CONTROL_STEP_S: f64 = 0.001;

/// Bus Watchdog unit: 20 ms per count.
pub const BUS_WATCHDOG_UNIT_S: f64 = 0.020;

/// Realtime Tick wraps after this value (ms).
pub const REALTIME_TICK_WRAP: u64 = 32768;

/// Present Input Voltage reported by the simulated servo (0.1 V units). Default 120 (12.0 V).
pub const SIM_INPUT_VOLTAGE: i64 = 120;

/// Present Temperature reported by the simulated servo (°C). Default 30.
pub const SIM_TEMPERATURE: i64 = 30;

fn layout() -> &'static Layout {
    static LAYOUT: OnceLock<Layout> = OnceLock::new();
    LAYOUT.get_or_init(Layout::xl430)
}

/// Pulses per second for one velocity unit (0.229 rpm).
fn velocity_unit_pps() -> f64 {
    VELOCITY_UNIT_RPM / 60.0 * PULSES_PER_REV
}

/// Pulses per second² for one Profile Acceleration unit (214.577 rev/min²).
fn acceleration_unit_pps2() -> f64 {
    ACCELERATION_UNIT_RPM_PER_MIN / 3600.0 * PULSES_PER_REV
}

/// What a servo is on the simulated bench.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Turns the mechanism's driver; moves under its own control when torque is on.
    Driver,
    /// Torque-off absolute encoder on the follower joint; its shaft is positioned by the
    /// plant model.
    Follower,
}

/// A Factory Reset option (parameter 1 of the instruction).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResetKind {
    /// 0xFF: everything.
    All,
    /// 0x01: everything except the ID.
    KeepId,
    /// 0x02: everything except the ID and the baud rate.
    KeepIdAndBaud,
}

/// A profile in progress in a position mode.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PositionProfile {
    /// Target in the servo frame (pulses, without homing offset).
    target: f64,
}

/// One simulated servo.
#[derive(Debug, Clone)]
pub struct Servo {
    table: [u8; TABLE_SIZE],
    role: Role,
    /// Shaft position in the servo frame (pulses, without homing offset, with the
    /// multi-turn offset applied).
    pos: f64,
    /// Velocity in the servo frame (pulses/s).
    vel: f64,
    /// Multi-turn offset (a multiple of 4096) added to a follower's plant position.
    turn_offset: f64,
    profile: Option<PositionProfile>,
    registered: Option<(u16, Vec<u8>)>,
    boot_s: f64,
    last_instruction_s: f64,
    now_s: f64,
    /// The shaft is blocked: it does not move, and no error is reported.
    blocked: bool,
}

impl Servo {
    /// A servo fresh from the factory (ID 1) with the given ID written, powered on at
    /// `now_s` with its shaft at `shaft_pulses` (physical frame).
    pub fn new(id: u8, role: Role, shaft_pulses: f64, now_s: f64) -> Self {
        let mut table = layout().defaults();
        table[usize::from(addr::ID)] = id;
        let mut s = Self {
            table,
            role,
            pos: shaft_pulses,
            vel: 0.0,
            turn_offset: 0.0,
            profile: None,
            registered: None,
            boot_s: now_s,
            last_instruction_s: now_s,
            now_s,
            blocked: false,
        };
        // Power-on: the present position is absolute within one rotation.
        s.reset_turns();
        s.refresh_live();
        s
    }

    /// Current ID (address 7).
    pub fn id(&self) -> u8 {
        self.table[usize::from(addr::ID)]
    }

    /// Secondary ID (address 12); 253..=255 means none.
    pub fn secondary_id(&self) -> Option<u8> {
        let s = self.table[usize::from(addr::SECONDARY_ID)];
        (s <= 252).then_some(s)
    }

    /// Role on the bench.
    pub fn role(&self) -> Role {
        self.role
    }

    fn u8_at(&self, a: u16) -> u8 {
        self.table[usize::from(a)]
    }

    fn value(&self, a: u16) -> i64 {
        let (it, _) = layout().at(usize::from(a)).expect("known item");
        it.decode(&self.table[usize::from(a)..usize::from(a) + usize::from(it.size)])
    }

    fn set_value(&mut self, a: u16, v: i64) {
        let (it, _) = layout().at(usize::from(a)).expect("known item");
        let bytes = (v as u32).to_le_bytes();
        let s = usize::from(a);
        self.table[s..s + usize::from(it.size)].copy_from_slice(&bytes[..usize::from(it.size)]);
    }

    /// Status Return Level (0 ping only, 1 ping and reads, 2 all).
    pub fn status_return_level(&self) -> u8 {
        self.u8_at(addr::STATUS_RETURN_LEVEL)
    }

    /// Return Delay Time in seconds (address 9, 2 µs units).
    pub fn return_delay_s(&self) -> f64 {
        f64::from(self.u8_at(addr::RETURN_DELAY_TIME)) * 2e-6
    }

    /// Baud rate selected in the control table (bit/s), from the index at address 8.
    pub fn baud_rate(&self) -> u32 {
        baud_for_index(self.u8_at(addr::BAUD_RATE))
    }

    /// Whether torque is on.
    pub fn torque_enabled(&self) -> bool {
        self.u8_at(addr::TORQUE_ENABLE) == 1
    }

    /// Operating Mode (address 11).
    pub fn operating_mode(&self) -> u8 {
        self.u8_at(addr::OPERATING_MODE)
    }

    /// Hardware Error Status (address 70).
    pub fn hardware_error(&self) -> u8 {
        self.u8_at(addr::HARDWARE_ERROR_STATUS)
    }

    /// The alert bit to put in this servo's status packets.
    pub fn alert(&self) -> u8 {
        if self.hardware_error() != 0 {
            err::ALERT
        } else {
            0
        }
    }

    /// Whether the bus watchdog has tripped (Bus Watchdog reads −1).
    pub fn watchdog_tripped(&self) -> bool {
        self.value(addr::BUS_WATCHDOG) == -1
    }

    fn reversed(&self) -> bool {
        self.u8_at(addr::DRIVE_MODE) & 0x01 != 0
    }

    /// Shaft angle in the physical (non-reversed) frame, pulses.
    pub fn shaft_pulses(&self) -> f64 {
        if self.reversed() {
            -self.pos
        } else {
            self.pos
        }
    }

    /// Shaft velocity in the physical frame, pulses/s.
    pub fn shaft_velocity_pps(&self) -> f64 {
        if self.reversed() {
            -self.vel
        } else {
            self.vel
        }
    }

    /// Position the shaft from outside (a torque-off follower moved by the mechanism):
    /// `shaft_pulses` in the physical frame, continuous; `dt` since the previous call for
    /// the velocity estimate.
    pub fn set_shaft_position(&mut self, shaft_pulses: f64, dt: f64) {
        let frame = if self.reversed() {
            -shaft_pulses
        } else {
            shaft_pulses
        };
        let new_pos = frame + self.turn_offset;
        if dt > 0.0 {
            self.vel = (new_pos - self.pos) / dt;
        }
        self.pos = new_pos;
    }

    /// Reset the multi-turn count so the present position is within one rotation.
    fn reset_turns(&mut self) {
        let homing = self.value(addr::HOMING_OFFSET) as f64;
        let present = self.pos + homing;
        let turns = (present / PULSES_PER_REV).floor() * PULSES_PER_REV;
        self.pos -= turns;
        self.turn_offset -= turns;
        if let Some(p) = &mut self.profile {
            p.target -= turns;
        }
    }

    /// Block the shaft (a jammed mechanism, a stalled gearbox): it stops where it is with
    /// no error reported, as a servo does until its overload detection trips.
    pub fn block(&mut self) {
        self.blocked = true;
        self.vel = 0.0;
        self.refresh_live();
    }

    /// Latch hardware error bits (fault injection). Bits in the Shutdown mask turn torque off.
    pub fn inject_hardware_error(&mut self, bits: u8) {
        let latched = self.hardware_error() | bits;
        self.table[usize::from(addr::HARDWARE_ERROR_STATUS)] = latched;
        if latched & self.u8_at(addr::SHUTDOWN) != 0 {
            self.torque_off();
        }
        self.refresh_live();
    }

    fn torque_off(&mut self) {
        self.table[usize::from(addr::TORQUE_ENABLE)] = 0;
        if self.role == Role::Driver {
            self.vel = 0.0;
        }
        self.profile = None;
    }

    /// Note that an instruction addressed to this servo arrived (feeds the bus watchdog).
    pub fn note_instruction(&mut self, now_s: f64) {
        self.last_instruction_s = now_s;
    }

    /// Advance the servo's own motion to `now_s` (driver role; a follower's shaft is set by
    /// the bus). Also runs the bus watchdog.
    pub fn advance(&mut self, now_s: f64) {
        if now_s <= self.now_s {
            return;
        }
        // Watchdog: checked against the interval since the last instruction.
        let wd = self.value(addr::BUS_WATCHDOG);
        if self.torque_enabled() && (1..=127).contains(&wd) {
            let limit = wd as f64 * BUS_WATCHDOG_UNIT_S;
            if now_s - self.last_instruction_s > limit {
                let trip_at = (self.last_instruction_s + limit).max(self.now_s);
                self.integrate(trip_at);
                self.trip_watchdog();
            }
        }
        self.integrate(now_s);
        self.refresh_live();
    }

    fn trip_watchdog(&mut self) {
        // e-manual: the servo stops, Profile Acceleration/Velocity become 0, Bus Watchdog -1.
        self.set_value(addr::BUS_WATCHDOG, -1);
        self.set_value(addr::PROFILE_ACCELERATION, 0);
        self.set_value(addr::PROFILE_VELOCITY, 0);
        self.set_value(addr::GOAL_VELOCITY, 0);
        self.set_value(addr::GOAL_PWM, 0);
        self.vel = 0.0;
        self.profile = None;
        let homing = self.value(addr::HOMING_OFFSET) as f64;
        self.set_value(addr::GOAL_POSITION, (self.pos + homing).round() as i64);
    }

    fn integrate(&mut self, until_s: f64) {
        while self.now_s < until_s {
            let dt = (until_s - self.now_s).min(CONTROL_STEP_S);
            if self.role == Role::Driver {
                self.control_step(dt);
            }
            self.now_s += dt;
        }
        self.now_s = until_s;
    }

    fn control_step(&mut self, dt: f64) {
        if !self.torque_enabled() || self.blocked {
            self.vel = 0.0;
            return;
        }
        let accel_raw = self.value(addr::PROFILE_ACCELERATION) as f64;
        let accel = if accel_raw > 0.0 {
            accel_raw * acceleration_unit_pps2()
        } else {
            f64::INFINITY
        };
        match self.operating_mode() {
            mode::VELOCITY | mode::PWM => {
                let target = if self.watchdog_tripped() {
                    0.0
                } else if self.operating_mode() == mode::VELOCITY {
                    self.value(addr::GOAL_VELOCITY) as f64 * velocity_unit_pps()
                } else {
                    self.value(addr::GOAL_PWM) as f64 / PWM_FULL_SCALE * NO_LOAD_SPEED_RPM / 60.0
                        * PULSES_PER_REV
                };
                let accel = if self.operating_mode() == mode::PWM {
                    f64::INFINITY
                } else {
                    accel
                };
                let v0 = self.vel;
                let v1 = approach(v0, target, accel * dt);
                // A step change (no profile) takes effect at once; a ramp integrates exactly.
                let v_mean = if accel.is_finite() {
                    0.5 * (v0 + v1)
                } else {
                    v1
                };
                self.pos += v_mean * dt;
                self.vel = v1;
            }
            mode::POSITION | mode::EXTENDED_POSITION => {
                let Some(profile) = self.profile else {
                    self.vel = 0.0;
                    return;
                };
                let prof_vel = self.value(addr::PROFILE_VELOCITY) as f64;
                let vlim = self.value(addr::VELOCITY_LIMIT) as f64;
                let vmax = if prof_vel > 0.0 {
                    prof_vel
                } else {
                    vlim.max(1.0)
                } * velocity_unit_pps();
                let err = profile.target - self.pos;
                let desired = if accel.is_finite() {
                    err.signum() * vmax.min((2.0 * accel * err.abs()).sqrt())
                } else {
                    err.signum() * vmax.min(err.abs() / dt)
                };
                let v0 = self.vel;
                let v1 = approach(v0, desired, accel * dt);
                let v_mean = if accel.is_finite() {
                    0.5 * (v0 + v1)
                } else {
                    v1
                };
                let new_pos = self.pos + v_mean * dt;
                let remaining = profile.target - new_pos;
                // Arrived (or would overshoot): land on the target and end the profile.
                if remaining.signum() != err.signum() || remaining.abs() < 0.25 {
                    self.pos = profile.target;
                    self.vel = 0.0;
                    self.profile = None;
                    return;
                }
                self.pos = new_pos;
                self.vel = v1;
            }
            _ => self.vel = 0.0,
        }
    }

    /// Recompute the read-only live items from the physical state.
    fn refresh_live(&mut self) {
        let homing = self.value(addr::HOMING_OFFSET) as f64;
        let present = (self.pos + homing).round() as i64;
        let vel_units = (self.vel / velocity_unit_pps()).round() as i64;
        self.set_value(addr::PRESENT_POSITION, present);
        self.set_value(addr::PRESENT_VELOCITY, vel_units);
        let tick_ms = (((self.now_s - self.boot_s).max(0.0)) * 1000.0) as u64 % REALTIME_TICK_WRAP;
        self.set_value(addr::REALTIME_TICK, tick_ms as i64);
        let torque = self.torque_enabled();
        let position_mode = matches!(
            self.operating_mode(),
            mode::POSITION | mode::EXTENDED_POSITION
        );
        let threshold = self.value(addr::MOVING_THRESHOLD);
        let moving = vel_units.abs() > threshold;
        self.set_value(addr::MOVING, i64::from(moving));
        let mut status = 0u8;
        if let Some(p) = self.profile {
            status |= 0x02; // profile ongoing
            self.set_value(
                addr::POSITION_TRAJECTORY,
                (p.target + homing).round() as i64,
            );
        } else {
            self.set_value(addr::POSITION_TRAJECTORY, present);
        }
        if torque && position_mode {
            let goal = self.value(addr::GOAL_POSITION);
            if self.profile.is_none() && (goal - present).abs() <= 1 {
                status |= 0x01; // in position
            }
            let pv = self.value(addr::PROFILE_VELOCITY);
            let pa = self.value(addr::PROFILE_ACCELERATION);
            status |= match (pv, pa) {
                (0, _) => 0x00,
                (_, 0) => 0x10,
                _ => 0x30,
            };
        }
        self.set_value(addr::MOVING_STATUS, i64::from(status));
        self.set_value(
            addr::VELOCITY_TRAJECTORY,
            if torque { vel_units } else { 0 },
        );
        let pwm = if torque {
            (vel_units as f64 * VELOCITY_UNIT_RPM / NO_LOAD_SPEED_RPM * PWM_FULL_SCALE).round()
                as i64
        } else {
            0
        };
        self.set_value(addr::PRESENT_PWM, pwm.clamp(-885, 885));
        self.set_value(addr::PRESENT_LOAD, 0);
        self.set_value(addr::PRESENT_INPUT_VOLTAGE, SIM_INPUT_VOLTAGE);
        self.set_value(addr::PRESENT_TEMPERATURE, SIM_TEMPERATURE);
        self.set_value(
            addr::REGISTERED_INSTRUCTION,
            i64::from(self.registered.is_some()),
        );
    }

    /// Resolve an address through indirect addressing: Indirect Data `n` stands for the
    /// byte at Indirect Address `n`.
    fn resolve(&self, address: u16) -> u16 {
        match super::control_table::indirect_slot_of_data(address) {
            Some(n) => {
                let a = super::control_table::indirect_address_addr(n);
                let target = u16::from_le_bytes([
                    self.table[usize::from(a)],
                    self.table[usize::from(a) + 1],
                ]);
                // An indirect address pointing at indirect data is the data byte itself.
                if super::control_table::indirect_slot_of_data(target).is_some() {
                    address
                } else {
                    target
                }
            }
            None => address,
        }
    }

    /// Read `len` bytes from `address` (Read / Sync Read / Bulk Read). Reserved bytes read
    /// as 0; reading past the end of the table is an Access error.
    pub fn read(&mut self, address: u16, len: u16) -> Result<Vec<u8>, u8> {
        let end = usize::from(address) + usize::from(len);
        if len == 0 {
            return Err(err::DATA_LENGTH);
        }
        if end > TABLE_SIZE {
            return Err(err::ACCESS);
        }
        self.refresh_live();
        Ok((address..address + len)
            .map(|a| self.table[usize::from(self.resolve(a))])
            .collect())
    }

    /// Validate a write of `data` at `address` without applying it; on success return the
    /// items to set with their new values, in address order.
    fn plan_write(&self, address: u16, data: &[u8]) -> Result<Vec<(Item, i64)>, u8> {
        if data.is_empty() {
            return Err(err::DATA_LENGTH);
        }
        if usize::from(address) + data.len() > TABLE_SIZE {
            return Err(err::ACCESS);
        }
        // Byte-level targets after indirect resolution.
        let mut staged = self.table;
        let mut touched: Vec<(Item, Vec<bool>)> = Vec::new();
        for (k, &b) in data.iter().enumerate() {
            let a = self.resolve(address + k as u16);
            let Some((it, idx)) = layout().at(usize::from(a)) else {
                return Err(err::ACCESS);
            };
            if it.access == Access::Read {
                return Err(err::ACCESS);
            }
            if it.area() == Area::Eeprom && self.torque_enabled() {
                return Err(err::ACCESS);
            }
            staged[usize::from(a)] = b;
            match touched.iter_mut().find(|(t, _)| t.address == it.address) {
                Some((_, seen)) => seen[usize::from(idx)] = true,
                None => {
                    let mut seen = vec![false; usize::from(it.size)];
                    seen[usize::from(idx)] = true;
                    touched.push((it, seen));
                }
            }
        }
        let mut plan = Vec::with_capacity(touched.len());
        for (it, seen) in touched {
            if seen.iter().any(|s| !s) {
                return Err(err::DATA_LENGTH);
            }
            let s = usize::from(it.address);
            let v = it.decode(&staged[s..s + usize::from(it.size)]);
            self.check_value(&it, v, &staged)?;
            plan.push((it, v));
        }
        plan.sort_by_key(|(it, _)| it.address);
        Ok(plan)
    }

    fn check_value(&self, it: &Item, v: i64, staged: &[u8; TABLE_SIZE]) -> Result<(), u8> {
        let staged_value = |a: u16| {
            let (item, _) = layout().at(usize::from(a)).expect("known item");
            item.decode(&staged[usize::from(a)..usize::from(a) + usize::from(item.size)])
        };
        let is_goal = matches!(
            it.address,
            addr::GOAL_PWM | addr::GOAL_VELOCITY | addr::GOAL_POSITION
        );
        if is_goal && self.watchdog_tripped() {
            return Err(err::DATA_RANGE);
        }
        match it.range {
            Range::Any => Ok(()),
            Range::Fixed(lo, hi) => {
                if (lo..=hi).contains(&v) {
                    Ok(())
                } else {
                    Err(err::DATA_RANGE)
                }
            }
            Range::SymmetricLimit(limit_addr) => {
                let limit = staged_value(limit_addr);
                if v.abs() <= limit {
                    Ok(())
                } else {
                    Err(err::DATA_LIMIT)
                }
            }
            Range::GoalPosition => {
                let ok = match staged[usize::from(addr::OPERATING_MODE)] {
                    mode::POSITION => (staged_value(addr::MIN_POSITION_LIMIT)
                        ..=staged_value(addr::MAX_POSITION_LIMIT))
                        .contains(&v),
                    _ => (-EXTENDED_POSITION_LIMIT..=EXTENDED_POSITION_LIMIT).contains(&v),
                };
                if ok {
                    Ok(())
                } else {
                    Err(err::DATA_LIMIT)
                }
            }
            Range::BusWatchdog => {
                if (0..=127).contains(&v) {
                    Ok(())
                } else {
                    Err(err::DATA_RANGE)
                }
            }
        }
    }

    /// Write `data` at `address` (Write / Sync Write / Bulk Write / Action). The whole write
    /// is validated first; on any error nothing changes and the error number is returned.
    pub fn write(&mut self, address: u16, data: &[u8]) -> Result<(), u8> {
        let plan = self.plan_write(address, data)?;
        if plan
            .iter()
            .any(|(it, v)| it.address == addr::TORQUE_ENABLE && *v == 1)
            && self.hardware_error() & self.u8_at(addr::SHUTDOWN) != 0
        {
            // A latched shutdown error keeps torque off until reboot.
            return Err(err::RESULT_FAIL);
        }
        for (it, v) in plan {
            self.apply(it, v);
        }
        self.refresh_live();
        Ok(())
    }

    fn apply(&mut self, it: Item, v: i64) {
        let old = self.value(it.address);
        self.set_value(it.address, v);
        match it.address {
            addr::TORQUE_ENABLE if old != v => {
                if v == 1 {
                    self.vel = 0.0;
                    if self.operating_mode() == mode::POSITION {
                        self.reset_turns();
                    }
                    // Hold the present position.
                    let homing = self.value(addr::HOMING_OFFSET) as f64;
                    self.set_value(addr::GOAL_POSITION, (self.pos + homing).round() as i64);
                    self.profile = None;
                } else {
                    self.torque_off();
                }
            }
            addr::OPERATING_MODE if old != v => {
                self.set_value(addr::PROFILE_VELOCITY, 0);
                self.set_value(addr::PROFILE_ACCELERATION, 0);
                let pwm_limit = self.value(addr::PWM_LIMIT);
                self.set_value(addr::GOAL_PWM, pwm_limit);
                self.set_value(addr::GOAL_VELOCITY, 0);
                if v == i64::from(mode::POSITION) {
                    self.reset_turns();
                }
            }
            addr::DRIVE_MODE if (old ^ v) & 0x01 != 0 => {
                // Reversing the direction mirrors the frame.
                self.pos = -self.pos;
                self.vel = -self.vel;
                self.turn_offset = -self.turn_offset;
            }
            addr::GOAL_POSITION if self.torque_enabled() && self.role == Role::Driver => {
                let homing = self.value(addr::HOMING_OFFSET) as f64;
                self.profile = Some(PositionProfile {
                    target: v as f64 - homing,
                });
            }
            _ => {}
        }
    }

    /// Register a write for a later Action (Reg Write). Validated now, like a write.
    pub fn reg_write(&mut self, address: u16, data: &[u8]) -> Result<(), u8> {
        self.plan_write(address, data)?;
        self.registered = Some((address, data.to_vec()));
        self.refresh_live();
        Ok(())
    }

    /// Execute the registered write (Action). Instruction error when none is registered.
    pub fn action(&mut self) -> Result<(), u8> {
        let Some((address, data)) = self.registered.take() else {
            return Err(err::INSTRUCTION);
        };
        let r = self.write(address, &data);
        self.refresh_live();
        r
    }

    /// Whether a write is registered.
    pub fn has_registered(&self) -> bool {
        self.registered.is_some()
    }

    /// Reboot: RAM back to defaults, EEPROM kept, position absolute within one rotation,
    /// realtime tick restarts.
    pub fn reboot(&mut self, now_s: f64) {
        let defaults = layout().defaults();
        let ram_start = usize::from(addr::TORQUE_ENABLE);
        self.table[ram_start..].copy_from_slice(&defaults[ram_start..]);
        self.profile = None;
        self.registered = None;
        if self.role == Role::Driver {
            self.vel = 0.0;
        }
        self.boot_s = now_s;
        self.last_instruction_s = now_s;
        self.reset_turns();
        self.refresh_live();
    }

    /// Factory Reset with the given option, then the servo reboots.
    pub fn factory_reset(&mut self, kind: ResetKind, now_s: f64) {
        let id = self.id();
        let baud = self.u8_at(addr::BAUD_RATE);
        let was_reversed = self.reversed();
        self.table = layout().defaults();
        match kind {
            ResetKind::All => {}
            ResetKind::KeepId => self.table[usize::from(addr::ID)] = id,
            ResetKind::KeepIdAndBaud => {
                self.table[usize::from(addr::ID)] = id;
                self.table[usize::from(addr::BAUD_RATE)] = baud;
            }
        }
        if was_reversed {
            self.pos = -self.pos;
            self.vel = -self.vel;
            self.turn_offset = -self.turn_offset;
        }
        self.reboot(now_s);
    }

    /// Clear instruction (option 0x01): reset the multi-turn count. Result Fail while moving.
    pub fn clear_multi_turn(&mut self) -> Result<(), u8> {
        if self.vel.abs() > 0.5 || self.profile.is_some() {
            return Err(err::RESULT_FAIL);
        }
        self.reset_turns();
        self.refresh_live();
        Ok(())
    }

    /// Present Position as reported (pulses, with homing offset).
    pub fn present_position(&self) -> i32 {
        self.value(addr::PRESENT_POSITION) as i32
    }

    /// Present Velocity as reported (0.229 rpm units).
    pub fn present_velocity(&self) -> i32 {
        self.value(addr::PRESENT_VELOCITY) as i32
    }

    /// Model number and firmware version for a ping reply.
    pub fn ping_params(&self) -> [u8; 3] {
        [
            self.table[0],
            self.table[1],
            self.table[usize::from(addr::FIRMWARE_VERSION)],
        ]
    }
}

/// Move `v` toward `target` by at most `step` (infinite step jumps).
fn approach(v: f64, target: f64, step: f64) -> f64 {
    if !step.is_finite() {
        return target;
    }
    if (target - v).abs() <= step {
        target
    } else {
        v + step * (target - v).signum()
    }
}

/// Bit rate for a Baud Rate index (address 8); unknown indices give 57600.
pub fn baud_for_index(index: u8) -> u32 {
    match index {
        0 => 9_600,
        2 => 115_200,
        3 => 1_000_000,
        4 => 2_000_000,
        5 => 3_000_000,
        6 => 4_000_000,
        7 => 4_500_000,
        _ => 57_600,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn driver() -> Servo {
        Servo::new(1, Role::Driver, 1000.0, 0.0)
    }

    /// Guards the e-manual's write error rules: reserved and read-only addresses, partial
    /// items, ranges, limits and the EEPROM lock.
    #[test]
    fn write_errors_follow_e_manual_rules() {
        let mut s = driver();
        assert_eq!(s.write(66, &[1]), Err(err::ACCESS), "reserved");
        assert_eq!(
            s.write(addr::PRESENT_POSITION, &[0, 0, 0, 0]),
            Err(err::ACCESS),
            "read only"
        );
        assert_eq!(
            s.write(addr::GOAL_VELOCITY, &[1, 0]),
            Err(err::DATA_LENGTH),
            "partial item"
        );
        assert_eq!(s.write(addr::ID, &[253]), Err(err::DATA_RANGE));
        assert_eq!(
            s.write(addr::GOAL_VELOCITY, &300i32.to_le_bytes()),
            Err(err::DATA_LIMIT),
            "above Velocity Limit 265"
        );
        assert_eq!(
            s.write(addr::GOAL_POSITION, &5000i32.to_le_bytes()),
            Err(err::DATA_LIMIT),
            "position mode limits"
        );
        assert_eq!(s.write(addr::OPERATING_MODE, &[mode::VELOCITY]), Ok(()));
        assert_eq!(s.write(addr::TORQUE_ENABLE, &[1]), Ok(()));
        assert_eq!(
            s.write(addr::OPERATING_MODE, &[mode::EXTENDED_POSITION]),
            Err(err::ACCESS),
            "EEPROM locked"
        );
        assert_eq!(s.write(addr::TORQUE_ENABLE, &[0]), Ok(()));
        assert_eq!(
            s.write(addr::OPERATING_MODE, &[mode::EXTENDED_POSITION]),
            Ok(())
        );
        // A failed multi-item write changes nothing.
        let mut data = vec![1u8, 1]; // torque on, LED on ...
        data.extend_from_slice(&[0, 0]); // ... and reserved 66, 67
        assert_eq!(s.write(addr::TORQUE_ENABLE, &data), Err(err::ACCESS));
        assert!(!s.torque_enabled());
    }

    /// Guards velocity mode with a profile acceleration: the speed ramps at the profile rate
    /// and the position integrates it.
    #[test]
    fn velocity_mode_ramps_and_integrates() {
        let mut s = driver();
        s.write(addr::OPERATING_MODE, &[mode::VELOCITY]).unwrap();
        s.write(addr::PROFILE_ACCELERATION, &10i32.to_le_bytes())
            .unwrap();
        s.write(addr::TORQUE_ENABLE, &[1]).unwrap();
        let p0 = s.present_position();
        s.write(addr::GOAL_VELOCITY, &200i32.to_le_bytes()).unwrap();
        // 10 × 214.577 rev/min² = 35.76 rpm/s: 17.9 rpm = 78 units after 0.5 s; 200 units after 1.28 s.
        s.advance(0.5);
        let v_half = s.present_velocity();
        assert!((77..=79).contains(&v_half), "ramp at 0.5 s: {v_half}");
        s.advance(3.0);
        assert_eq!(s.present_velocity(), 200);
        let expected_pulses = {
            let v = 200.0 * velocity_unit_pps();
            let t_ramp = v / (10.0 * acceleration_unit_pps2());
            v * (3.0 - t_ramp) + 0.5 * v * t_ramp
        };
        let moved = f64::from(s.present_position() - p0);
        assert!(
            (moved - expected_pulses).abs() < 2.0,
            "{moved} vs {expected_pulses}"
        );
    }

    /// Guards the trapezoidal position profile in extended position mode: the servo arrives
    /// at a multi-turn goal, reports in-position, and took about the profile's time.
    #[test]
    fn extended_position_profile_reaches_goal() {
        let mut s = driver();
        s.write(addr::OPERATING_MODE, &[mode::EXTENDED_POSITION])
            .unwrap();
        s.write(addr::TORQUE_ENABLE, &[1]).unwrap();
        s.write(addr::PROFILE_VELOCITY, &100i32.to_le_bytes())
            .unwrap();
        s.write(addr::PROFILE_ACCELERATION, &20i32.to_le_bytes())
            .unwrap();
        let goal = s.present_position() + 3 * 4096;
        s.write(addr::GOAL_POSITION, &goal.to_le_bytes()).unwrap();
        let mut t = 0.0;
        let mut arrived = None;
        while t < 20.0 {
            t += 0.01;
            s.advance(t);
            if arrived.is_none()
                && s.present_position() == goal
                && s.u8_at(addr::MOVING_STATUS) & 0x01 != 0
            {
                arrived = Some(t);
            }
        }
        let v = 100.0 * velocity_unit_pps();
        let a = 20.0 * acceleration_unit_pps2();
        let expected = 3.0 * 4096.0 / v + v / a;
        let arrived = arrived.expect("goal reached");
        assert!((arrived - expected).abs() < 0.05, "{arrived} vs {expected}");
        assert_eq!(s.present_velocity(), 0);
    }

    /// Guards the bus watchdog: silence longer than the watchdog period stops the motor,
    /// sets −1 and refuses goal writes with a Data Range error until cleared.
    #[test]
    fn bus_watchdog_stops_and_locks_goals() {
        let mut s = driver();
        s.write(addr::OPERATING_MODE, &[mode::VELOCITY]).unwrap();
        s.write(addr::TORQUE_ENABLE, &[1]).unwrap();
        s.write(addr::BUS_WATCHDOG, &[5]).unwrap(); // 100 ms
        s.write(addr::GOAL_VELOCITY, &100i32.to_le_bytes()).unwrap();
        s.note_instruction(0.0);
        s.advance(0.05);
        assert_eq!(s.present_velocity(), 100);
        s.note_instruction(0.05);
        s.advance(0.14);
        assert!(!s.watchdog_tripped(), "90 ms of silence is within 100 ms");
        s.advance(0.2);
        assert!(s.watchdog_tripped());
        assert_eq!(s.present_velocity(), 0);
        assert_eq!(s.read(addr::BUS_WATCHDOG, 1), Ok(vec![0xFF]));
        assert_eq!(
            s.write(addr::GOAL_VELOCITY, &50i32.to_le_bytes()),
            Err(err::DATA_RANGE)
        );
        s.write(addr::BUS_WATCHDOG, &[0]).unwrap();
        assert_eq!(s.write(addr::GOAL_VELOCITY, &50i32.to_le_bytes()), Ok(()));
    }

    /// Guards Reg Write / Action and the Registered Instruction flag.
    #[test]
    fn reg_write_waits_for_action() {
        let mut s = driver();
        assert_eq!(s.action(), Err(err::INSTRUCTION));
        s.reg_write(addr::LED, &[1]).unwrap();
        assert_eq!(s.read(addr::LED, 1), Ok(vec![0]));
        assert_eq!(s.read(addr::REGISTERED_INSTRUCTION, 1), Ok(vec![1]));
        s.action().unwrap();
        assert_eq!(s.read(addr::LED, 1), Ok(vec![1]));
        assert_eq!(s.read(addr::REGISTERED_INSTRUCTION, 1), Ok(vec![0]));
    }

    /// Guards indirect addressing: Indirect Data 1..4 mapped onto Present Position read it.
    #[test]
    fn indirect_data_reads_its_target() {
        let mut s = driver();
        for k in 0..4u16 {
            let a = super::super::control_table::indirect_address_addr(usize::from(k) + 1);
            s.write(a, &(addr::PRESENT_POSITION + k).to_le_bytes())
                .unwrap();
        }
        let direct = s.read(addr::PRESENT_POSITION, 4).unwrap();
        assert_eq!(s.read(addr::INDIRECT_DATA_1, 4).unwrap(), direct);
    }

    /// Guards torque-off multi-turn behaviour and reset on reboot: a follower's continuous
    /// position survives many turns and becomes absolute within one rotation on reboot.
    #[test]
    fn follower_position_is_continuous_until_reboot() {
        let mut s = Servo::new(2, Role::Follower, 0.0, 0.0);
        s.set_shaft_position(5.0 * 4096.0 + 100.0, 0.1);
        s.advance(0.1);
        assert_eq!(s.present_position(), 5 * 4096 + 100);
        s.reboot(0.2);
        assert_eq!(s.present_position(), 100);
        s.set_shaft_position(5.0 * 4096.0 + 200.0, 0.1);
        s.advance(0.3);
        assert_eq!(s.present_position(), 200);
    }

    /// Guards the realtime tick: milliseconds since boot, wrapping at 32768.
    #[test]
    fn realtime_tick_counts_milliseconds_and_wraps() {
        let mut s = driver();
        s.advance(1.234);
        assert_eq!(
            s.read(addr::REALTIME_TICK, 2),
            Ok(1234u16.to_le_bytes().to_vec())
        );
        s.advance(33.0);
        assert_eq!(
            s.read(addr::REALTIME_TICK, 2),
            Ok(((33_000 % 32_768) as u16).to_le_bytes().to_vec())
        );
    }

    /// Guards hardware error injection: overload latches, alerts, turns torque off (default
    /// Shutdown mask 52) and blocks torque on until reboot.
    #[test]
    fn hardware_error_shuts_down_and_alerts() {
        let mut s = driver();
        s.write(addr::TORQUE_ENABLE, &[1]).unwrap();
        s.inject_hardware_error(super::super::control_table::hw_error::OVERLOAD);
        assert!(!s.torque_enabled());
        assert_eq!(s.alert(), err::ALERT);
        assert_eq!(s.write(addr::TORQUE_ENABLE, &[1]), Err(err::RESULT_FAIL));
        s.reboot(1.0);
        // Hardware error status is RAM: cleared by reboot.
        assert_eq!(s.alert(), 0);
        assert_eq!(s.write(addr::TORQUE_ENABLE, &[1]), Ok(()));
    }
}
