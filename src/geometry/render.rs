//! Shaded pictures of a [`Scene`] at a key time: what a person looks at before printing.
//!
//! Owns a small software rasterizer and its look:
//! - **Camera**: orthographic, along one of the [`View`]s (isometric, front, top, right),
//!   fitted so that every part at every key time of the period stays in the picture with a
//!   [`FRAME_MARGIN`] (renders of different key times share one camera and can be flipped
//!   through).
//! - **Rasterizing**: each part's [`ShadedMesh`] (crease-split normals, as in the GLB) is
//!   posed, projected and drawn into a z-buffer at [`RenderOptions::supersample`]² samples
//!   per pixel; back faces are culled (parts are closed); depth and normals are interpolated
//!   per sample.
//! - **Shading**: Lambert from a key and a fill light fixed to the camera, a sky/ground
//!   ambient term and a soft Blinn–Phong highlight, on the part's (linear) colour; alpha is
//!   ignored.
//! - **Outlines** (optional, on by default): samples where the part changes, where depth
//!   jumps (its second difference exceeds [`OUTLINE_DEPTH_SAMPLES`] sample widths) or where
//!   the normal turns by more than [`OUTLINE_NORMAL_DEG`] are drawn in a dark line colour,
//!   so silhouettes and printed edges read clearly.
//! - **Resolve**: samples averaged in linear light, then encoded as sRGB, over a neutral
//!   light-grey gradient background; [`Image::write_png`] writes 8-bit RGB PNG.
//!
//! Everything is single-threaded f64/f32 arithmetic in a fixed order, so the same scene gives
//! byte-identical pictures. It does not choose which key times or views a report shows
//! (that is `build`'s job) and draws no text.

use std::borrow::Cow;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use crate::geometry::scene::{Pose, Scene};
use crate::geometry::shading::{first_unfit, shade_scene, ShadedMesh};

/// Default picture size, pixels (width, height): large enough to see a groove, small enough
/// for a report page (≈ 100–300 kB as PNG).
pub const DEFAULT_SIZE_PX: [u32; 2] = [1200, 900];

/// Default samples per pixel along each axis. 3 (9 samples per pixel) gives edges without
/// visible steps; memory is 12 bytes per sample (≈ 117 MB at the default size).
pub const DEFAULT_SUPERSAMPLE: u32 = 3;

/// Free border around the fitted parts, as a fraction of the picture's width or height.
pub const FRAME_MARGIN: f64 = 0.06;

/// A depth second difference above this many sample widths marks an outline. A plane has
/// none at any angle; a curved surface only reaches it within a couple of samples of its
/// silhouette; a part in front of another (or of itself) jumps by millimetres.
pub const OUTLINE_DEPTH_SAMPLES: f64 = 2.0;

/// Normals of neighbouring samples turning by more than this mark an outline (a crease).
/// Below [`CREASE_ANGLE_DEG`](crate::geometry::shading::CREASE_ANGLE_DEG), so every edge
/// the shading splits is drawn; far above the turn between neighbouring samples of a smooth
/// surface (well under a degree).
pub const OUTLINE_NORMAL_DEG: f64 = 30.0;

/// Most keys of a part whose vertices the camera fit looks at (evenly spread). A part
/// turning once per period then moves at most 5° between the keys looked at, which misses
/// at most 0.1 % of its radius: far inside [`FRAME_MARGIN`].
pub const FIT_KEYS: usize = 72;

/// Largest supersampling factor accepted (memory grows with its square).
pub const MAX_SUPERSAMPLE: u32 = 4;

/// Largest picture side accepted, pixels.
pub const MAX_SIZE_PX: u32 = 8192;

/// Outline colour, linear RGB (a dark neutral grey, sRGB ≈ #2e2e2e).
const OUTLINE_RGB: [f32; 3] = [0.027, 0.027, 0.027];
/// Background gradient, linear RGB, top and bottom (sRGB ≈ #f6f6f4 and #d6d9de).
const BACKGROUND_TOP: [f32; 3] = [0.922, 0.922, 0.905];
const BACKGROUND_BOTTOM: [f32; 3] = [0.672, 0.694, 0.730];

/// A viewing direction (orthographic).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum View {
    /// From (+1, −1, +1): front, right and above at once.
    Isometric,
    /// From −y, z up.
    Front,
    /// From +z, y up.
    Top,
    /// From +x, z up.
    Right,
}

impl View {
    /// All views, in the order reports show them.
    pub const ALL: [View; 4] = [View::Isometric, View::Front, View::Top, View::Right];

    /// A short name for file names ("isometric", "front", "top", "right").
    pub fn name(self) -> &'static str {
        match self {
            View::Isometric => "isometric",
            View::Front => "front",
            View::Top => "top",
            View::Right => "right",
        }
    }

    /// Camera axes in the world: right, up, toward the viewer (right-handed, orthonormal).
    fn axes(self) -> [[f64; 3]; 3] {
        let (toward, world_up) = match self {
            View::Isometric => ([1.0, -1.0, 1.0], [0.0, 0.0, 1.0]),
            View::Front => ([0.0, -1.0, 0.0], [0.0, 0.0, 1.0]),
            View::Top => ([0.0, 0.0, 1.0], [0.0, 1.0, 0.0]),
            View::Right => ([1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
        };
        let toward = normalize(toward);
        let right = normalize(cross(world_up, toward));
        let up = cross(toward, right);
        [right, up, toward]
    }
}

/// Picture settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// Width and height, pixels.
    pub size_px: [u32; 2],
    /// Samples per pixel along each axis (1 = no anti-aliasing).
    pub supersample: u32,
    /// Draw silhouettes and creases.
    pub outlines: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            size_px: DEFAULT_SIZE_PX,
            supersample: DEFAULT_SUPERSAMPLE,
            outlines: true,
        }
    }
}

/// Why a picture could not be made or written.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The options are out of range.
    #[error(
        "picture {}×{} px at {supersample}× supersampling: sides must be 1..={MAX_SIZE_PX} px \
         and supersampling 1..={MAX_SUPERSAMPLE}",
        size_px[0], size_px[1]
    )]
    Options {
        /// The size asked for.
        size_px: [u32; 2],
        /// The supersampling asked for.
        supersample: u32,
    },
    /// The scene has more parts than the renderer tells apart.
    #[error("the scene has {0} parts; at most {max} can be rendered", max = u16::MAX)]
    TooManyParts(usize),
    /// A part has no pose at the key asked for.
    #[error("part {part:?} has {poses} poses; there is no key {key}")]
    NoPose {
        /// The part.
        part: String,
        /// Its pose count.
        poses: usize,
        /// The key asked for.
        key: usize,
    },
    /// A part's mesh refers to a vertex it does not have, or has a coordinate that is not
    /// finite.
    #[error("part {part:?}: {what}")]
    BadMesh {
        /// The part.
        part: String,
        /// What is wrong.
        what: String,
    },
    /// The PNG could not be written.
    #[error("{path}: {message}")]
    Write {
        /// The file.
        path: PathBuf,
        /// The reason.
        message: String,
    },
}

/// An 8-bit sRGB picture, rows top to bottom.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Image {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// `width × height × 3` bytes, R G B per pixel.
    pub rgb: Vec<u8>,
}

impl Image {
    /// The pixel at (x, y) from the top left.
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        let i = 3 * (y as usize * self.width as usize + x as usize);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    /// The picture as PNG bytes.
    pub fn png_bytes(&self) -> Vec<u8> {
        let mut out = Vec::new();
        self.encode(&mut out)
            .expect("encoding a well-sized RGB picture into memory cannot fail");
        out
    }

    /// Write the picture as a PNG file.
    pub fn write_png(&self, path: &Path) -> Result<(), RenderError> {
        let err = |message: String| RenderError::Write {
            path: path.to_path_buf(),
            message,
        };
        let file = std::fs::File::create(path).map_err(|e| err(e.to_string()))?;
        let mut w = std::io::BufWriter::new(file);
        self.encode(&mut w).map_err(|e| err(e.to_string()))?;
        std::io::Write::flush(&mut w).map_err(|e| err(e.to_string()))
    }

    fn encode(&self, w: impl std::io::Write) -> Result<(), png::EncodingError> {
        let mut enc = png::Encoder::new(w, self.width, self.height);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let mut writer = enc.write_header()?;
        writer.write_image_data(&self.rgb)?;
        writer.finish()
    }
}

/// A scene prepared for rendering: shading meshes built once, each view's camera fitted
/// once, any number of pictures.
pub struct Renderer<'a> {
    scene: &'a Scene,
    shaded: Cow<'a, [ShadedMesh]>,
    options: RenderOptions,
    /// The camera of each of [`View::ALL`], fitted on first use.
    cameras: [OnceLock<Camera>; View::ALL.len()],
}

/// The z-buffer and what each sample saw.
struct Samples {
    width: usize,
    height: usize,
    /// Depth toward the viewer (larger is nearer), mm; −∞ where nothing was drawn.
    depth: Vec<f32>,
    /// Unit normal in camera axes, scaled to i16.
    normal: Vec<[i16; 3]>,
    /// Part index, or [`NONE`].
    part: Vec<u16>,
}

/// No part at this sample.
const NONE: u16 = u16::MAX;

impl<'a> Renderer<'a> {
    /// Check the options and the scene's meshes, and build the shading meshes.
    pub fn new(scene: &'a Scene, options: RenderOptions) -> Result<Renderer<'a>, RenderError> {
        Self::check(scene, &options)?;
        Ok(Renderer {
            scene,
            shaded: Cow::Owned(shade_scene(scene)),
            options,
            cameras: Default::default(),
        })
    }

    /// [`Renderer::new`] with the shading made already ([`shade_scene`] of `scene`, or of
    /// a scene whose parts these are): each shading must fit its part's mesh.
    pub fn with_shading(
        scene: &'a Scene,
        shaded: &'a [ShadedMesh],
        options: RenderOptions,
    ) -> Result<Renderer<'a>, RenderError> {
        Self::check(scene, &options)?;
        if let Some(part) = first_unfit(scene, shaded) {
            return Err(RenderError::BadMesh {
                part: part.name.clone(),
                what: "no shading made from its mesh was given for it".into(),
            });
        }
        Ok(Renderer {
            scene,
            shaded: Cow::Borrowed(shaded),
            options,
            cameras: Default::default(),
        })
    }

    /// The options in range, and every part's mesh indexable and finite.
    fn check(scene: &Scene, options: &RenderOptions) -> Result<(), RenderError> {
        let [w, h] = options.size_px;
        let ok_side = |s: u32| (1..=MAX_SIZE_PX).contains(&s);
        if !ok_side(w) || !ok_side(h) || !(1..=MAX_SUPERSAMPLE).contains(&options.supersample) {
            return Err(RenderError::Options {
                size_px: options.size_px,
                supersample: options.supersample,
            });
        }
        if scene.parts.len() >= usize::from(NONE) {
            return Err(RenderError::TooManyParts(scene.parts.len()));
        }
        for part in &scene.parts {
            let nv = part.mesh.vertices.len();
            let bad = |what: String| RenderError::BadMesh {
                part: part.name.clone(),
                what,
            };
            if let Some(i) = part
                .mesh
                .triangles
                .iter()
                .position(|t| t.iter().any(|&v| v as usize >= nv))
            {
                return Err(bad(format!(
                    "triangle {i} refers to a vertex it does not have"
                )));
            }
            if let Some(i) = part
                .mesh
                .vertices
                .iter()
                .position(|v| v.iter().any(|x| !x.is_finite()))
            {
                return Err(bad(format!("vertex {i} is not finite")));
            }
        }
        Ok(())
    }

    /// The picture of the scene at key `key` seen along `view`.
    pub fn render(&self, key: usize, view: View) -> Result<Image, RenderError> {
        for part in &self.scene.parts {
            if part.poses.is_empty() || (part.poses.len() != 1 && key >= part.poses.len()) {
                return Err(RenderError::NoPose {
                    part: part.name.clone(),
                    poses: part.poses.len(),
                    key,
                });
            }
        }
        let ss = self.options.supersample as usize;
        let [w, h] = self.options.size_px.map(|s| s as usize * ss);
        let slot = View::ALL
            .iter()
            .position(|&v| v == view)
            .expect("every view is in ALL");
        let camera =
            self.cameras[slot].get_or_init(|| Camera::fit(self.scene, view.axes(), [w, h]));
        let mut samples = Samples {
            width: w,
            height: h,
            depth: vec![f32::NEG_INFINITY; w * h],
            normal: vec![[0; 3]; w * h],
            part: vec![NONE; w * h],
        };
        for (i, (part, shaded)) in self.scene.parts.iter().zip(self.shaded.iter()).enumerate() {
            let pose = part.pose(key);
            let screen: Vec<[f64; 3]> = shaded
                .positions
                .iter()
                .map(|&p| camera.project(pose.apply(p)))
                .collect();
            let normals: Vec<[f64; 3]> = shaded
                .normals
                .iter()
                .map(|&n| camera.turn(pose.rotate(n)))
                .collect();
            for t in &shaded.triangles {
                let v = t.map(|k| k as usize);
                samples.triangle(
                    [screen[v[0]], screen[v[1]], screen[v[2]]],
                    [normals[v[0]], normals[v[1]], normals[v[2]]],
                    i as u16,
                );
            }
        }
        let colors: Vec<[f32; 3]> = self
            .scene
            .parts
            .iter()
            .map(|p| [p.color[0], p.color[1], p.color[2]].map(|c| c.clamp(0.0, 1.0)))
            .collect();
        let outline = Outline {
            depth_mm: (OUTLINE_DEPTH_SAMPLES / camera.px_per_mm) as f32,
            cos_normal: OUTLINE_NORMAL_DEG.to_radians().cos() as f32,
        };
        Ok(samples.resolve(ss, &colors, self.options.outlines.then_some(outline)))
    }
}

/// Orthographic camera: world → (sample x, sample y, depth toward the viewer in mm).
struct Camera {
    axes: [[f64; 3]; 3],
    /// World-axis coordinates (right, up) shown at the picture's centre, mm.
    center: [f64; 2],
    /// Samples per mm.
    px_per_mm: f64,
    /// Picture centre, samples.
    mid: [f64; 2],
}

impl Camera {
    /// Fit every part over the period: the extents along the picture's axes of each
    /// part's vertices at up to [`FIT_KEYS`] evenly spread keys.
    fn fit(scene: &Scene, axes: [[f64; 3]; 3], [w, h]: [usize; 2]) -> Camera {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for part in &scene.parts {
            let stride = part.poses.len().div_ceil(FIT_KEYS).max(1);
            for pose in part.poses.iter().step_by(stride) {
                // The picture's axes in the part's frame (turned by the inverse rotation),
                // and where the part's origin lands.
                let [qw, qx, qy, qz] = pose.rotation;
                let inverse = Pose {
                    rotation: [qw, -qx, -qy, -qz],
                    translation: [0.0; 3],
                };
                let local = [0, 1].map(|k| inverse.rotate(axes[k]));
                let origin = [0, 1].map(|k| dot(pose.translation, axes[k]));
                for v in &part.mesh.vertices {
                    for k in 0..2 {
                        let x = origin[k] + dot(*v, local[k]);
                        lo[k] = lo[k].min(x);
                        hi[k] = hi[k].max(x);
                    }
                }
            }
        }
        if lo[0] > hi[0] {
            (lo, hi) = ([-1.0; 2], [1.0; 2]); // nothing to see: any camera
        }
        let span = [0, 1].map(|k| (hi[k] - lo[k]).max(1e-9));
        let usable = 1.0 - 2.0 * FRAME_MARGIN;
        let px_per_mm = (usable * w as f64 / span[0]).min(usable * h as f64 / span[1]);
        Camera {
            axes,
            center: [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])],
            px_per_mm,
            mid: [0.5 * w as f64, 0.5 * h as f64],
        }
    }

    fn project(&self, p: [f64; 3]) -> [f64; 3] {
        [
            self.mid[0] + (dot(p, self.axes[0]) - self.center[0]) * self.px_per_mm,
            self.mid[1] - (dot(p, self.axes[1]) - self.center[1]) * self.px_per_mm,
            dot(p, self.axes[2]),
        ]
    }

    /// A world direction in camera axes (right, up, toward the viewer).
    fn turn(&self, n: [f64; 3]) -> [f64; 3] {
        [
            dot(n, self.axes[0]),
            dot(n, self.axes[1]),
            dot(n, self.axes[2]),
        ]
    }
}

impl Samples {
    /// Draw one triangle (screen positions, camera-axis normals) for part `part`.
    fn triangle(&mut self, p: [[f64; 3]; 3], n: [[f64; 3]; 3], part: u16) {
        let edge = |a: [f64; 3], b: [f64; 3], x: f64, y: f64| {
            (b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0])
        };
        let area = edge(p[0], p[1], p[2][0], p[2][1]);
        // Screen y points down, so a face turned to the viewer winds clockwise on screen.
        if area >= 0.0 || !area.is_finite() {
            return;
        }
        let (w, h) = (self.width as f64, self.height as f64);
        let min_x = p.iter().map(|q| q[0]).fold(f64::INFINITY, f64::min);
        let max_x = p.iter().map(|q| q[0]).fold(f64::NEG_INFINITY, f64::max);
        let min_y = p.iter().map(|q| q[1]).fold(f64::INFINITY, f64::min);
        let max_y = p.iter().map(|q| q[1]).fold(f64::NEG_INFINITY, f64::max);
        if max_x < 0.0 || max_y < 0.0 || min_x >= w || min_y >= h {
            return;
        }
        // Sample centres at integer + 0.5 inside the box.
        let x0 = (min_x - 0.5).ceil().max(0.0) as usize;
        let x1 = ((max_x - 0.5).floor().min(w - 1.0)) as isize;
        let y0 = (min_y - 0.5).ceil().max(0.0) as usize;
        let y1 = ((max_y - 0.5).floor().min(h - 1.0)) as isize;
        if x1 < x0 as isize || y1 < y0 as isize {
            return;
        }
        let inv = 1.0 / area;
        for y in y0..=y1 as usize {
            let sy = y as f64 + 0.5;
            let row = y * self.width;
            for x in x0..=x1 as usize {
                let sx = x as f64 + 0.5;
                let l0 = edge(p[1], p[2], sx, sy) * inv;
                let l1 = edge(p[2], p[0], sx, sy) * inv;
                let l2 = 1.0 - l0 - l1;
                if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                    continue;
                }
                let z = (l0 * p[0][2] + l1 * p[1][2] + l2 * p[2][2]) as f32;
                let i = row + x;
                if z <= self.depth[i] {
                    continue;
                }
                let m = [0, 1, 2].map(|k| l0 * n[0][k] + l1 * n[1][k] + l2 * n[2][k]);
                let len = dot(m, m).sqrt();
                let m = if len > 0.0 {
                    m.map(|c| c / len)
                } else {
                    [0.0, 0.0, 1.0]
                };
                self.depth[i] = z;
                self.normal[i] = m.map(|c| (c * f64::from(i16::MAX)).round() as i16);
                self.part[i] = part;
            }
        }
    }

    /// Is the sample at (x, y) on an outline (see the module doc)?
    fn is_edge(&self, x: usize, y: usize, rule: &Outline) -> bool {
        let i = y * self.width + x;
        let me = self.part[i];
        // Neighbours along x and along y: (before, after), each if inside the picture.
        let lines = [
            (
                (x > 0).then(|| i - 1),
                (x + 1 < self.width).then_some(i + 1),
            ),
            (
                (y > 0).then(|| i - self.width),
                (y + 1 < self.height).then_some(i + self.width),
            ),
        ];
        for (before, after) in lines {
            let neighbours = [before, after].into_iter().flatten();
            if neighbours.clone().any(|j| self.part[j] != me) {
                return true;
            }
            if me == NONE {
                continue;
            }
            if let (Some(a), Some(b)) = (before, after) {
                let d2 = self.depth[a] - 2.0 * self.depth[i] + self.depth[b];
                if d2.abs() > rule.depth_mm {
                    return true;
                }
            }
            let ni = unpack(self.normal[i]);
            for j in neighbours {
                let nj = unpack(self.normal[j]);
                if ni[0] * nj[0] + ni[1] * nj[1] + ni[2] * nj[2] < rule.cos_normal {
                    return true;
                }
            }
        }
        false
    }

    /// Average each pixel's samples in linear light and encode as sRGB.
    fn resolve(&self, ss: usize, colors: &[[f32; 3]], outline: Option<Outline>) -> Image {
        let light = Lighting::new();
        let (ow, oh) = (self.width / ss, self.height / ss);
        let mut rgb = Vec::with_capacity(ow * oh * 3);
        let inv = 1.0 / (ss * ss) as f32;
        for oy in 0..oh {
            for ox in 0..ow {
                let mut acc = [0.0f32; 3];
                for sy in 0..ss {
                    let y = oy * ss + sy;
                    for sx in 0..ss {
                        let x = ox * ss + sx;
                        let i = y * self.width + x;
                        let c = if outline.as_ref().is_some_and(|o| self.is_edge(x, y, o)) {
                            OUTLINE_RGB
                        } else if self.part[i] == NONE {
                            background((y as f32 + 0.5) / self.height as f32)
                        } else {
                            light.shade(colors[self.part[i] as usize], unpack(self.normal[i]))
                        };
                        for k in 0..3 {
                            acc[k] += c[k];
                        }
                    }
                }
                rgb.extend(acc.map(|c| srgb_byte(c * inv)));
            }
        }
        Image {
            width: ow as u32,
            height: oh as u32,
            rgb,
        }
    }
}

/// Background at height fraction `v` (0 top, 1 bottom), linear RGB.
fn background(v: f32) -> [f32; 3] {
    [0, 1, 2].map(|k| BACKGROUND_TOP[k] + (BACKGROUND_BOTTOM[k] - BACKGROUND_TOP[k]) * v)
}

/// When a sample lies on an outline.
struct Outline {
    /// Depth second difference above which it does, mm.
    depth_mm: f32,
    /// Cosine of the normal turn above which it does.
    cos_normal: f32,
}

/// A normal stored as i16 → unit f32.
fn unpack(n: [i16; 3]) -> [f32; 3] {
    n.map(|c| f32::from(c) / f32::from(i16::MAX))
}

/// Two lights fixed to the camera (axes right, up, toward the viewer) and the highlight's
/// half vector.
struct Lighting {
    /// Key light from the upper left, in front.
    key: [f32; 3],
    /// Fill light from the right, slightly below.
    fill: [f32; 3],
    /// Half vector of the key light and the view direction (+z).
    half: [f32; 3],
}

impl Lighting {
    fn new() -> Lighting {
        let unit = |v: [f32; 3]| {
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            v.map(|x| x / l)
        };
        let key = unit([-2.0, 3.0, 3.3]);
        Lighting {
            key,
            fill: unit([3.0, -0.5, 2.5]),
            half: unit([key[0], key[1], key[2] + 1.0]),
        }
    }

    /// The lit colour of a surface of linear base colour `c` with camera-axis normal `n`:
    /// sky/ground ambient, two Lambert terms and a soft white highlight (satin plastic).
    fn shade(&self, c: [f32; 3], n: [f32; 3]) -> [f32; 3] {
        let d = |l: [f32; 3]| (n[0] * l[0] + n[1] * l[1] + n[2] * l[2]).max(0.0);
        let ambient = 0.16 + 0.06 * n[1];
        let diffuse = 0.72 * d(self.key) + 0.28 * d(self.fill);
        let spec = 0.18 * d(self.half).powi(48);
        c.map(|x| (x * (ambient + diffuse) + spec).min(1.0))
    }
}

/// Linear [0, 1] → 8-bit sRGB.
fn srgb_byte(x: f32) -> u8 {
    let x = x.clamp(0.0, 1.0);
    let s = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalize(a: [f64; 3]) -> [f64; 3] {
    let l = dot(a, a).sqrt();
    a.map(|x| x / l)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::primitive_meshes::cuboid;
    use crate::geometry::scene::ScenePart;

    const RED: [f32; 4] = [0.8, 0.08, 0.06, 1.0];
    const BLUE: [f32; 4] = [0.06, 0.2, 0.8, 1.0];

    fn part(name: &str, min: [f64; 3], max: [f64; 3], color: [f32; 4]) -> ScenePart {
        ScenePart {
            name: name.into(),
            mesh: cuboid(min, max),
            color,
            poses: vec![Pose::IDENTITY],
        }
    }

    /// Two 10 mm cubes 10 mm apart along x.
    fn two_cubes() -> Scene {
        Scene {
            parts: vec![
                part("red", [0.0; 3], [10.0; 3], RED),
                part("blue", [20.0, 0.0, 0.0], [30.0, 10.0, 10.0], BLUE),
            ],
            times_s: vec![0.0],
        }
    }

    fn options(w: u32, h: u32, supersample: u32, outlines: bool) -> RenderOptions {
        RenderOptions {
            size_px: [w, h],
            supersample,
            outlines,
        }
    }

    /// The encoded colour of a face looking straight at the camera.
    fn facing(c: [f32; 4]) -> [u8; 3] {
        Lighting::new()
            .shade([c[0], c[1], c[2]], [0.0, 0.0, 1.0])
            .map(srgb_byte)
    }

    /// The encoded background of pixel row `y` of `h` at supersampling `ss` (the mean of
    /// its sample rows).
    fn background_px(y: u32, h: u32, ss: u32) -> [u8; 3] {
        let mut acc = [0.0f32; 3];
        for s in 0..ss {
            let v = ((y * ss + s) as f32 + 0.5) / (h * ss) as f32;
            let b = background(v);
            for k in 0..3 {
                acc[k] += b[k] * ss as f32;
            }
        }
        acc.map(|c| srgb_byte(c / (ss * ss) as f32))
    }

    /// Guards camera fit, projection, rasterization and shading: seen from the front at
    /// 300 × 200 px, the cubes fill the squares the fit predicts (x 18–106 and 194–282,
    /// y 56–144: 8.8 px/mm, centred); every pixel 2 px inside a square has exactly its
    /// cube's lit colour, and every pixel 2 px outside both is exactly the background.
    #[test]
    fn two_cubes_cover_the_expected_pixels() {
        let scene = two_cubes();
        let img = Renderer::new(&scene, options(300, 200, 3, true))
            .unwrap()
            .render(0, View::Front)
            .unwrap();
        let squares = [(18.0, 106.0, RED), (194.0, 282.0, BLUE)];
        let (top, bottom) = (56.0, 144.0);
        let mut inside = [0usize; 2];
        for y in 0..200u32 {
            for x in 0..300u32 {
                let (cx, cy) = (x as f64 + 0.5, y as f64 + 0.5);
                let px = img.pixel(x, y);
                let mut outside_all = true;
                for (k, &(x0, x1, color)) in squares.iter().enumerate() {
                    let dist_in = (cx - x0).min(x1 - cx).min(cy - top).min(bottom - cy);
                    if dist_in > 2.0 {
                        assert_eq!(px, facing(color), "({x}, {y}) inside square {k}");
                        inside[k] += 1;
                    }
                    if dist_in > -2.0 {
                        outside_all = false;
                    }
                }
                if outside_all {
                    assert_eq!(px, background_px(y, 200, 3), "({x}, {y}) is background");
                }
            }
        }
        assert_eq!(inside, [84 * 84; 2]);
    }

    /// Guards shading made once for several uses (`build` shades each part once for the GLB
    /// and five pictures): the picture is the one [`Renderer::new`] draws, also for a part
    /// taken alone with its own shading, and shading made from another mesh is refused,
    /// naming the part.
    #[test]
    fn shading_made_once_draws_the_same_and_must_fit() {
        let big = part("big", [0.0; 3], [20.0; 3], BLUE);
        let small = part("small", [5.0, -5.0, 5.0], [15.0, 0.0, 15.0], RED);
        let scene = Scene {
            parts: vec![big, small],
            times_s: vec![0.0],
        };
        let shaded = shade_scene(&scene);
        let draw = |r: Renderer<'_>| r.render(0, View::Isometric).unwrap();
        assert_eq!(
            draw(Renderer::with_shading(&scene, &shaded, options(120, 120, 2, true)).unwrap()),
            draw(Renderer::new(&scene, options(120, 120, 2, true)).unwrap())
        );
        let alone = Scene {
            parts: vec![scene.parts[1].clone()],
            times_s: vec![0.0],
        };
        assert_eq!(
            draw(
                Renderer::with_shading(
                    &alone,
                    std::slice::from_ref(&shaded[1]),
                    options(120, 120, 2, true)
                )
                .unwrap()
            ),
            draw(Renderer::new(&alone, options(120, 120, 2, true)).unwrap())
        );
        let sphere = crate::geometry::primitive_meshes::uv_sphere([0.0; 3], 3.0, 16, 8);
        let wrong = [ShadedMesh::new(&sphere, 40.0), shaded[1].clone()];
        // Another mesh's shading, then none at all for the second part.
        for (given, part) in [(&wrong[..], "big"), (&shaded[..1], "small")] {
            let e = Renderer::with_shading(&scene, given, options(120, 120, 2, true))
                .err()
                .expect("refused");
            assert_eq!(
                e.to_string(),
                format!("part {part:?}: no shading made from its mesh was given for it")
            );
        }
    }

    /// Guards the z-buffer and culling: a small cube in front of a large one shows over it
    /// whichever part is drawn first.
    #[test]
    fn nearer_part_wins_in_any_order() {
        let big = part("big", [0.0; 3], [20.0; 3], BLUE);
        let small = part("small", [5.0, -5.0, 5.0], [15.0, 0.0, 15.0], RED);
        let mut scene = Scene {
            parts: vec![big, small],
            times_s: vec![0.0],
        };
        let a = Renderer::new(&scene, options(200, 200, 2, true))
            .unwrap()
            .render(0, View::Isometric)
            .unwrap();
        scene.parts.reverse();
        let b = Renderer::new(&scene, options(200, 200, 2, true))
            .unwrap()
            .render(0, View::Isometric)
            .unwrap();
        assert_eq!(a, b);
        // From the front, the small cube covers the centre of the big one.
        let img = Renderer::new(&scene, options(200, 200, 2, false))
            .unwrap()
            .render(0, View::Front)
            .unwrap();
        assert_eq!(img.pixel(100, 100), facing(RED));
        assert_eq!(img.pixel(30, 30), facing(BLUE));
    }

    /// Guards the anti-aliasing: without supersampling a tilted edge has only pure face or
    /// background pixels; with it, the pixels along the edge take blends in between.
    #[test]
    fn supersampling_blends_edges() {
        let mut scene = two_cubes();
        scene.parts.truncate(1);
        let h = std::f64::consts::FRAC_PI_8.sin();
        scene.parts[0].poses = vec![Pose {
            rotation: [std::f64::consts::FRAC_PI_8.cos(), 0.0, 0.0, h],
            translation: [0.0; 3],
        }];
        let count_blends = |ss: u32| {
            let img = Renderer::new(&scene, options(120, 120, ss, false))
                .unwrap()
                .render(0, View::Top)
                .unwrap();
            let mut blends = 0;
            for y in 0..120 {
                for x in 0..120 {
                    let p = img.pixel(x, y);
                    let pure_face = p == facing(RED);
                    let pure_bg = p == background_px(y, 120, ss);
                    if !pure_face && !pure_bg {
                        blends += 1;
                    }
                }
            }
            blends
        };
        assert_eq!(count_blends(1), 0);
        assert!(count_blends(3) > 200, "{}", count_blends(3));
    }

    /// Guards the outlines: across the middle row, the silhouettes of a cube seen from the
    /// front are darker than its face with outlines on (a line of 2 samples over a 3-sample
    /// pixel), and nothing is darker than the face without them.
    #[test]
    fn outlines_darken_silhouettes() {
        let mut scene = two_cubes();
        scene.parts.truncate(1);
        let darkest = |outlines: bool| {
            let img = Renderer::new(&scene, options(100, 100, 3, outlines))
                .unwrap()
                .render(0, View::Front)
                .unwrap();
            (0..100)
                .map(|x| img.pixel(x, 50).iter().map(|&c| u32::from(c)).sum::<u32>())
                .min()
                .unwrap()
        };
        let face: u32 = facing(RED).iter().map(|&c| u32::from(c)).sum();
        assert!(
            darkest(true) * 10 < face * 9,
            "{} vs face {face}",
            darkest(true)
        );
        assert_eq!(darkest(false), face);
    }

    /// The same scene renders to the same bytes twice, and the PNG file decodes to them.
    #[test]
    fn deterministic_and_written_as_png() {
        let scene = two_cubes();
        let render = || {
            Renderer::new(&scene, RenderOptions::default())
                .unwrap()
                .render(0, View::Isometric)
                .unwrap()
        };
        let (a, b) = (render(), render());
        assert_eq!(a.png_bytes(), b.png_bytes());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cubes.png");
        a.write_png(&path).unwrap();
        let decoder = png::Decoder::new(std::fs::File::open(&path).unwrap());
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height), (1200, 900));
        assert_eq!(&buf[..info.buffer_size()], &a.rgb[..]);
    }

    /// A key that no pose has and out-of-range options are refused with the reason.
    #[test]
    fn bad_requests_are_refused() {
        let mut scene = two_cubes();
        scene.parts[1].poses = vec![Pose::IDENTITY; 3];
        let r = Renderer::new(&scene, RenderOptions::default()).unwrap();
        assert!(r.render(2, View::Top).is_ok());
        let e = r.render(3, View::Top).unwrap_err().to_string();
        assert_eq!(e, "part \"blue\" has 3 poses; there is no key 3");
        let e = Renderer::new(&scene, options(0, 10, 3, true))
            .err()
            .unwrap()
            .to_string();
        assert!(e.starts_with("picture 0×10 px at 3× supersampling"), "{e}");
        assert!(Renderer::new(&scene, options(10, 10, 5, true)).is_err());
    }
}
