//! Where the hubs, the follower's sensor features and the support go, by rule.
//!
//! Owns [`Layout`]: heights (everything that moves lies between `z_lo` and `z_hi`; the hubs
//! sit below it, the base plate below them, the AS5600 cap and its sensor arm above it),
//! the reach of each part, the pillar's place, and the solids of these features in each
//! part's frame ([`Pieces`]: what a part adds, what it cuts, and a ball cover of the
//! added material for planning). The joints per class: a 5 mm rod the follower's hub turns
//! on (1R) or slides and turns on (1R1T, a hub long enough for the stroke), a ball at the
//! joint centre (3R; its cup is planned by `connect`). Couplings per bench: a D-bore for a
//! NEMA 17 stepper's shaft, or a Dynamixel horn pattern with the hub reaching down through
//! the base to the horn. It does not plan anything around obstacles (`connect` does).

use std::sync::Arc;

use nalgebra::{Rotation3, Vector3};

use crate::geometry::sdf::{Cuboid, Cylinder, HalfSpace, Intersection, Sdf, Sphere, Vec3};
use crate::synth::closure::Class;

use super::bench::{Bench, Coupling, Reading};
use super::dims::*;
use super::kinematics::Frame;
use super::kinematics::Kinematics;
use super::swept::{swept_bounds, Balls};

/// Samples per period for the bounds of moving material. 720: the parts move by less than
/// a millimetre between samples, and the bounds are grown by the largest such move.
const BOUNDS_SAMPLES: usize = 720;
/// Height of the AS5600 magnet cap on top of the follower. 6 mm: the 2.7 mm pocket and a
/// 3.3 mm floor.
const CAP_HEIGHT_MM: f64 = 6.0;
/// Radius of the magnet cap. 6 mm: 2.9 mm of wall around the 6.2 mm pocket.
const CAP_RADIUS_MM: f64 = 6.0;
/// Linear-encoder flange on the follower hub: radial overhang beyond the hub and thickness.
const FLANGE_OVERHANG_MM: f64 = 7.0;
const FLANGE_THICKNESS_MM: f64 = 3.0;
/// Engagement of the 1R1T hub on its rod beyond the stroke. 10 mm.
const SLIDE_ENGAGEMENT_MM: f64 = 10.0;
/// Arm holding the AS5600 board: width and thickness.
const ARM_WIDTH_MM: f64 = 10.0;
const ARM_THICKNESS_MM: f64 = 5.0;
/// AS5600 board thickness (the chip faces the magnet from the board's underside).
const BOARD_THICKNESS_MM: f64 = 1.6;
/// Margin of the base plate around what stands on it. 8 mm.
const BASE_MARGIN_MM: f64 = 8.0;
/// Plunger linear encoder body the base's clamp boss holds: 8 mm, clamp 12 mm tall.
const PLUNGER_BODY_MM: f64 = 8.0;
const PLUNGER_CLAMP_MM: f64 = 12.0;

/// Solids a part adds and cuts in its own frame, and a ball cover of what it adds.
#[derive(Clone, Default)]
pub struct Pieces {
    /// Material added.
    pub add: Vec<Arc<dyn Sdf>>,
    /// Material removed (bores, holes, pockets) after everything is added.
    pub cut: Vec<Arc<dyn Sdf>>,
    /// Conservative cover of `add`, for planning.
    pub cover: Vec<Balls>,
}

/// Balls covering a cylinder (centre line sampled at the radius' spacing).
pub fn cover_cylinder(c: &Cylinder, frame: Frame) -> Balls {
    let step = c.radius.max(0.5);
    let n = (c.length / step).ceil().max(1.0) as usize;
    Balls {
        frame,
        centers: (0..=n)
            .map(|i| c.base + c.axis * (c.length * i as f64 / n as f64))
            .collect(),
        radius: c.radius.hypot(0.5 * step),
    }
}

/// Balls covering an axis-aligned box by a grid at the box's smallest half extent.
pub fn cover_box(min: Vec3, max: Vec3, frame: Frame) -> Balls {
    let size = max - min;
    let s = size.min().max(0.5);
    let n = [
        (size.x / s).ceil().max(1.0) as usize,
        (size.y / s).ceil().max(1.0) as usize,
        (size.z / s).ceil().max(1.0) as usize,
    ];
    let mut centers = Vec::new();
    for i in 0..=n[0] {
        for j in 0..=n[1] {
            for k in 0..=n[2] {
                centers.push(
                    min + Vec3::new(
                        size.x * i as f64 / n[0] as f64,
                        size.y * j as f64 / n[1] as f64,
                        size.z * k as f64 / n[2] as f64,
                    ),
                );
            }
        }
    }
    let cell = Vec3::new(
        size.x / n[0] as f64,
        size.y / n[1] as f64,
        size.z / n[2] as f64,
    );
    Balls {
        frame,
        centers,
        radius: 0.5 * cell.norm(),
    }
}

/// Heights, reaches and places of everything placed by rule.
#[derive(Clone, Debug)]
pub struct Layout {
    /// The class.
    pub class: Class,
    /// The bench.
    pub bench: Bench,
    /// Print clearance, mm.
    pub clearance: f64,
    /// d_x, mm.
    pub dx: f64,
    /// Lowest z any moving material reaches (reference frame), mm.
    pub z_lo: f64,
    /// Highest z any moving material reaches, mm.
    pub z_hi: f64,
    /// Follower translation along z over the period: (min, max), mm.
    pub stroke: (f64, f64),
    /// Largest distance of follower material from its axis (1R/1R1T) or centre (3R), mm.
    pub follower_reach: f64,
    /// Largest distance of driver material from the driver axis, mm.
    pub driver_reach: f64,
    /// Driver hub z range (driver frame; the same heights in R).
    pub driver_hub: (f64, f64),
    /// Follower hub z range in the follower frame (1R, 1R1T).
    pub follower_hub: Option<(f64, f64)>,
    /// Magnet cap z range in the follower frame (AS5600 reading).
    pub cap: Option<(f64, f64)>,
    /// Base plate z range (reference frame).
    pub base: (f64, f64),
    /// Pillar position (x, y) of the AS5600 arm.
    pub pillar: Option<[f64; 2]>,
    /// z of the AS5600 chip plane (reference frame).
    pub chip_z: Option<f64>,
    /// Magnet-to-chip air gap over the period: (min, max), mm.
    pub air_gap: Option<(f64, f64)>,
}

impl Layout {
    /// Place everything for the moving material covered by `follower` (follower frame)
    /// and `driver` (driver frame) balls.
    pub fn new(
        kin: &Kinematics,
        bench: &Bench,
        clearance: f64,
        follower: &[Balls],
        driver: &[Balls],
    ) -> Layout {
        let class = kin.class();
        let mut b = crate::geometry::mesh::Aabb::EMPTY;
        for body in follower.iter().chain(driver) {
            b = b.union(&swept_bounds(kin, body, Frame::Reference, BOUNDS_SAMPLES));
        }
        let (z_lo, z_hi) = (b.min[2], b.max[2]);
        let mut stroke = (0.0f64, 0.0f64);
        if class == Class::R1T1 {
            stroke = (f64::INFINITY, f64::NEG_INFINITY);
            for i in 0..BOUNDS_SAMPLES {
                let z = kin.follower(i as f64 / BOUNDS_SAMPLES as f64).translation.z;
                stroke = (stroke.0.min(z), stroke.1.max(z));
            }
        }
        let reach = |bodies: &[Balls], radial: bool| {
            bodies
                .iter()
                .flat_map(|s| {
                    s.centers.iter().map(move |c| {
                        if radial {
                            c.xy().norm() + s.radius
                        } else {
                            c.norm() + s.radius
                        }
                    })
                })
                .fold(0.0, f64::max)
        };
        let follower_reach = reach(follower, class != Class::R3);
        let driver_reach = reach(driver, true);
        let dx = kin.dx_mm();

        let driver_hub = (z_lo - HUB_GAP_MM - HUB_HEIGHT_MM, z_lo - HUB_GAP_MM);
        let follower_hub = (class != Class::R3).then(|| {
            let h = if class == Class::R1T1 {
                HUB_HEIGHT_MM.max(stroke.1 - stroke.0 + SLIDE_ENGAGEMENT_MM)
            } else {
                HUB_HEIGHT_MM
            };
            let top = z_lo - HUB_GAP_MM - stroke.1;
            (top - h, top)
        });
        let lowest_hub = follower_hub
            .map_or(driver_hub.0, |f| f.0 + stroke.0)
            .min(driver_hub.0);
        let base_top = lowest_hub - HUB_GAP_MM;
        let base = (base_top - BASE_THICKNESS_MM, base_top);

        let (cap, chip_z, air_gap) = if bench.reading == Reading::As5600 {
            let bottom = z_hi + HUB_GAP_MM - stroke.0;
            let cap = (bottom, bottom + CAP_HEIGHT_MM);
            let chip = cap.1 + stroke.1 + AS5600_AIR_GAP_MM;
            let gap = (AS5600_AIR_GAP_MM, AS5600_AIR_GAP_MM + stroke.1 - stroke.0);
            (Some(cap), Some(chip), Some(gap))
        } else {
            (None, None, None)
        };
        let pillar = chip_z.map(|_| {
            let need_f = follower_reach + SUPPORT_MARGIN_MM + PILLAR_RADIUS_MM;
            let need_d = driver_reach + SUPPORT_MARGIN_MM + PILLAR_RADIUS_MM;
            let mut r = need_f;
            loop {
                for deg in [180.0f64, 150.0, 210.0, 120.0, 240.0, 90.0, 270.0] {
                    let (s, c) = deg.to_radians().sin_cos();
                    let p = [r * c, r * s];
                    if (p[0] - dx).hypot(p[1]) >= need_d {
                        return p;
                    }
                }
                r += 10.0;
            }
        });
        Layout {
            class,
            bench: bench.clone(),
            clearance,
            dx,
            z_lo,
            z_hi,
            stroke,
            follower_reach,
            driver_reach,
            driver_hub,
            follower_hub,
            cap,
            base,
            pillar,
            chip_z,
            air_gap,
        }
    }

    /// The hub's lower end when it couples to a horn under the base: through the base.
    fn horn_bottom(&self) -> f64 {
        self.base.0 - 1.0
    }

    /// The follower's rule-placed features (follower frame).
    pub fn follower_pieces(&self) -> Pieces {
        let mut p = Pieces::default();
        let c = self.clearance;
        if let Some((z0, z1)) = self.follower_hub {
            let z0 = if self.bench.reading == Reading::ServoHorn {
                self.horn_bottom() - self.stroke.0
            } else {
                z0
            };
            let hub = Cylinder::z(0.0, 0.0, z0, z1, FOLLOWER_HUB_RADIUS_MM);
            p.cover.push(cover_cylinder(&hub, Frame::Follower));
            p.add.push(Arc::new(hub));
            match self.bench.reading {
                Reading::ServoHorn => horn_cuts(&mut p.cut, z0, z1, c),
                _ => {
                    // The rod's bore, through, at the rod's radius: the follower's shrink
                    // (`Design::follower_solid`) grows it by half the clearance, the fit
                    // of the driver's D-bore on the motor shaft. It used to add the whole
                    // clearance here as well: a 5.6 mm bore at the default 0.2 mm, 0.3 mm
                    // of radial play on the rod before the print's own error.
                    p.cut.push(Arc::new(Cylinder::z(
                        0.0,
                        0.0,
                        z0 - 1.0,
                        z1 + 1.0,
                        0.5 * FOLLOWER_SHAFT_MM,
                    )));
                }
            }
            if self.bench.linear_encoder {
                let f = Cylinder::z(
                    0.0,
                    0.0,
                    z0,
                    z0 + FLANGE_THICKNESS_MM,
                    FOLLOWER_HUB_RADIUS_MM + FLANGE_OVERHANG_MM,
                );
                p.cover.push(cover_cylinder(&f, Frame::Follower));
                p.add.push(Arc::new(f));
            }
        }
        if let Some((z0, z1)) = self.cap {
            let cap = Cylinder::z(0.0, 0.0, z0, z1, CAP_RADIUS_MM);
            p.cover.push(cover_cylinder(&cap, Frame::Follower));
            p.add.push(Arc::new(cap));
            p.cut.push(Arc::new(Cylinder::z(
                0.0,
                0.0,
                z1 - MAGNET_THICKNESS_MM - 0.2,
                z1 + 1.0,
                0.5 * MAGNET_DIAMETER_MM + 0.1,
            )));
        }
        if self.class == Class::R3 {
            let ball = Sphere {
                center: Vec3::zeros(),
                radius: BALL_RADIUS_MM - 0.5 * c,
            };
            p.cover.push(Balls {
                frame: Frame::Follower,
                centers: vec![Vec3::zeros()],
                radius: BALL_RADIUS_MM,
            });
            p.add.push(Arc::new(ball));
        }
        p
    }

    /// The driver's hub and coupling (driver frame).
    pub fn driver_pieces(&self) -> Pieces {
        let mut p = Pieces::default();
        let (mut z0, z1) = self.driver_hub;
        if self.bench.coupling == Coupling::Xl430Horn {
            z0 = self.horn_bottom();
        }
        let hub = Cylinder::z(0.0, 0.0, z0, z1, DRIVER_HUB_RADIUS_MM);
        p.cover.push(cover_cylinder(&hub, Frame::Driver));
        p.add.push(Arc::new(hub));
        let c = self.clearance;
        match self.bench.coupling {
            Coupling::Nema17 => {
                // D-bore: the shaft's circle cut by the flat, from the hub's bottom to 2 mm
                // below its top; an M3 set screw (2.5 mm tap drill) through the flat side.
                let r = 0.5 * NEMA17_SHAFT_MM + 0.5 * c;
                let flat = NEMA17_FLAT_MM - 0.5 * NEMA17_SHAFT_MM + 0.5 * c;
                let bore = Intersection::new(vec![
                    Box::new(Cylinder::z(0.0, 0.0, z0 - 1.0, z1 - 2.0, r)),
                    Box::new(HalfSpace {
                        point: Vec3::new(flat, 0.0, 0.0),
                        normal: Vec3::x(),
                        clip: crate::geometry::mesh::Aabb::new(
                            [-r, -r, z0 - 1.0],
                            [r, r, z1 - 2.0],
                        ),
                    }),
                ]);
                p.cut.push(Arc::new(bore));
                let zm = 0.5 * (z0 + z1 - 2.0);
                p.cut.push(Arc::new(Cylinder {
                    base: Vec3::new(0.0, 0.0, zm),
                    axis: Vec3::x(),
                    length: DRIVER_HUB_RADIUS_MM + 1.0,
                    radius: 1.25,
                }));
            }
            Coupling::Xl430Horn => horn_cuts(&mut p.cut, z0, z1, c),
        }
        p
    }

    /// The support (reference frame): base plate, rod boss, motor holes, and for the AS5600
    /// a pillar with an arm holding the board over the magnet. The 3R ball's cup and post
    /// are planned by `connect` and added there.
    pub fn support_pieces(&self) -> Pieces {
        let mut p = Pieces::default();
        let (b0, b1) = self.base;
        // Footprint: both hubs, the motor, the pillar.
        let mut lo = Vec3::new(-FOLLOWER_HUB_RADIUS_MM, -FOLLOWER_HUB_RADIUS_MM, b0);
        let mut hi = Vec3::new(FOLLOWER_HUB_RADIUS_MM, FOLLOWER_HUB_RADIUS_MM, b1);
        let motor_half = match self.bench.coupling {
            Coupling::Nema17 => 0.5 * NEMA17_BODY_MM,
            Coupling::Xl430Horn => 0.5 * XL430_BODY_MM[1],
        };
        lo.x = lo.x.min(self.dx - motor_half);
        hi.x = hi.x.max(self.dx + motor_half);
        lo.y = lo.y.min(-motor_half);
        hi.y = hi.y.max(motor_half);
        if self.class == Class::R3 {
            // The post to the ball lands somewhere below the joint: cover the follower's
            // reach under it.
            let r = 0.5 * self.follower_reach;
            lo.x = lo.x.min(-r);
            lo.y = lo.y.min(-r);
            hi.y = hi.y.max(r);
        }
        if let Some(pl) = self.pillar {
            lo.x = lo.x.min(pl[0] - PILLAR_RADIUS_MM);
            lo.y = lo.y.min(pl[1] - PILLAR_RADIUS_MM);
            hi.x = hi.x.max(pl[0] + PILLAR_RADIUS_MM);
            hi.y = hi.y.max(pl[1] + PILLAR_RADIUS_MM);
        }
        lo -= Vec3::new(BASE_MARGIN_MM, BASE_MARGIN_MM, 0.0);
        hi += Vec3::new(BASE_MARGIN_MM, BASE_MARGIN_MM, 0.0);
        p.cover.push(cover_box(lo, hi, Frame::Reference));
        p.add.push(Arc::new(Cuboid::aligned(lo, hi)));
        let c = self.clearance;
        // Driver motor.
        match self.bench.coupling {
            Coupling::Nema17 => {
                p.cut.push(Arc::new(Cylinder::z(
                    self.dx,
                    0.0,
                    b0 - 1.0,
                    b1 + 1.0,
                    0.5 * NEMA17_PILOT_HOLE_MM,
                )));
                let s = 0.5 * NEMA17_SCREW_SQUARE_MM;
                for (sx, sy) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
                    p.cut.push(Arc::new(Cylinder::z(
                        self.dx + sx * s,
                        sy * s,
                        b0 - 1.0,
                        b1 + 1.0,
                        0.5 * M3_CLEARANCE_MM,
                    )));
                }
            }
            Coupling::Xl430Horn => p.cut.push(Arc::new(Cylinder::z(
                self.dx,
                0.0,
                b0 - 1.0,
                b1 + 1.0,
                DRIVER_HUB_RADIUS_MM + SUPPORT_MARGIN_MM,
            ))),
        }
        // Follower joint.
        if let Some((fz0, _)) = self.follower_hub {
            if self.bench.reading == Reading::ServoHorn {
                p.cut.push(Arc::new(Cylinder::z(
                    0.0,
                    0.0,
                    b0 - 1.0,
                    b1 + 1.0,
                    FOLLOWER_HUB_RADIUS_MM + SUPPORT_MARGIN_MM,
                )));
            } else {
                // Boss up to just under the hub at its lowest, holding the rod. The rod itself
                // runs inside the hub's bore: it is the joint, not an obstacle.
                let top = fz0 + self.stroke.0 - c;
                let boss = Cylinder::z(0.0, 0.0, b1 - 0.5, top, FOLLOWER_HUB_RADIUS_MM - 1.0);
                p.cover.push(cover_cylinder(&boss, Frame::Reference));
                p.add.push(Arc::new(boss));
                p.cut.push(Arc::new(Cylinder::z(
                    0.0,
                    0.0,
                    b0 - 1.0,
                    top + 1.0,
                    0.5 * FOLLOWER_SHAFT_MM,
                )));
            }
            if self.bench.linear_encoder {
                // Clamp boss under the base for a plunger encoder pressing on the flange.
                let x = -(FOLLOWER_HUB_RADIUS_MM + 0.5 * FLANGE_OVERHANG_MM);
                let boss = Cylinder::z(
                    x,
                    0.0,
                    b0 - PLUNGER_CLAMP_MM,
                    b1,
                    0.5 * PLUNGER_BODY_MM + 3.0,
                );
                p.cover.push(cover_cylinder(&boss, Frame::Reference));
                p.add.push(Arc::new(boss));
                p.cut.push(Arc::new(Cylinder::z(
                    x,
                    0.0,
                    b0 - PLUNGER_CLAMP_MM - 1.0,
                    b1 + 1.0,
                    0.5 * PLUNGER_BODY_MM + c,
                )));
                p.cut.push(Arc::new(Cylinder {
                    base: Vec3::new(x, 0.0, b0 - 0.5 * PLUNGER_CLAMP_MM),
                    axis: -Vec3::x(),
                    length: 0.5 * PLUNGER_BODY_MM + 4.0,
                    radius: 1.25,
                }));
            }
        }
        // AS5600 pillar, arm and board pad.
        if let (Some(pl), Some(chip)) = (self.pillar, self.chip_z) {
            let pad0 = chip + BOARD_THICKNESS_MM;
            let top = pad0 + ARM_THICKNESS_MM;
            let pillar = Cylinder::z(pl[0], pl[1], b1 - 0.5, top, PILLAR_RADIUS_MM);
            p.cover.push(cover_cylinder(&pillar, Frame::Reference));
            p.add.push(Arc::new(pillar));
            // The arm: a beam from the pillar to over the axis, along the pillar's bearing.
            let len = pl[0].hypot(pl[1]);
            let ang = pl[1].atan2(pl[0]);
            let half = Vector3::new(0.5 * len, 0.5 * ARM_WIDTH_MM, 0.5 * ARM_THICKNESS_MM);
            let arm = Cuboid {
                center: Vec3::new(0.5 * pl[0], 0.5 * pl[1], pad0 + 0.5 * ARM_THICKNESS_MM),
                half,
                rotation: Rotation3::from_axis_angle(&Vector3::z_axis(), ang),
            };
            p.cover.push(Balls {
                frame: Frame::Reference,
                centers: (0..=(len / 2.0).ceil() as usize)
                    .map(|i| {
                        let s = (i as f64 * 2.0 / len).min(1.0);
                        Vec3::new(pl[0] * s, pl[1] * s, pad0 + 0.5 * ARM_THICKNESS_MM)
                    })
                    .collect(),
                radius: (0.5 * ARM_WIDTH_MM).hypot(0.5 * ARM_THICKNESS_MM) + 1.0,
            });
            p.add.push(Arc::new(arm));
            let pad_half = 0.5 * AS5600_BOARD_MM;
            let pad = Cuboid::aligned(
                Vec3::new(-pad_half, -pad_half, pad0),
                Vec3::new(pad_half, pad_half, top),
            );
            p.cover.push(cover_box(
                Vec3::new(-pad_half, -pad_half, pad0),
                Vec3::new(pad_half, pad_half, top),
                Frame::Reference,
            ));
            p.add.push(Arc::new(pad));
            let hs = 0.5 * AS5600_HOLE_SPACING_MM;
            for (hx, hy) in [(hs, hs), (-hs, -hs)] {
                p.cut.push(Arc::new(Cylinder::z(
                    hx,
                    hy,
                    pad0 - 1.0,
                    top + 1.0,
                    0.5 * M3_CLEARANCE_MM,
                )));
            }
        }
        p
    }
}

/// A Dynamixel horn pattern at the bottom `z0` of a hub reaching up to `z1`: a recess over
/// the horn and eight M2 clearance holes through the hub.
fn horn_cuts(cut: &mut Vec<Arc<dyn Sdf>>, z0: f64, z1: f64, c: f64) {
    cut.push(Arc::new(Cylinder::z(
        0.0,
        0.0,
        z0 - 1.0,
        z0 + 2.5,
        0.5 * XL430_HORN_RECESS_MM + c,
    )));
    for i in 0..XL430_HORN_HOLES {
        let a = std::f64::consts::TAU * i as f64 / XL430_HORN_HOLES as f64;
        let (x, y) = (
            0.5 * XL430_HORN_PCD_MM * a.cos(),
            0.5 * XL430_HORN_PCD_MM * a.sin(),
        );
        cut.push(Arc::new(Cylinder::z(
            x,
            y,
            z0 - 1.0,
            z1 + 1.0,
            0.5 * M2_CLEARANCE_MM,
        )));
    }
}
