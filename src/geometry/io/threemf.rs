//! 3MF packages: all parts of a mechanism in one file, laid out on a print bed.
//!
//! Owns the package we write and the bed layout. A 3MF is a zip (Open Packaging Conventions)
//! holding `[Content_Types].xml`, `_rels/.rels` (whose one relationship points at the model
//! part) and the model part at exactly [`MODEL_PART`]: one published 3MF crate names it
//! `3D/model.model`, and slicers and `trimesh` then find no model. The model is in
//! millimetres; each part is one `<object>` carrying its name, with its mesh in its own
//! frame, and one build `<item>` whose transform is the translation that places it on the
//! bed ([`layout`]). Coordinates are written as the shortest decimal that reads back to the
//! same `f32` (what slicers keep), so a package read back with [`read_3mf`] has exactly the
//! written meshes rounded to `f32`. The zip entries carry a fixed date, so the same parts
//! give the same bytes.
//!
//! [`read_3mf`] reads what we write and what the core specification allows of meshes and
//! build items (any namespace prefix, any element order); it refuses components, which we
//! never write, with that reason. It does not check meshes (use [`Mesh::check`]).

use std::borrow::Cow;
use std::fs::File;
use std::io::{BufWriter, Cursor, Read, Seek, Write};
use std::path::{Path, PathBuf};

use quick_xml::events::{BytesStart, Event};
use quick_xml::{Reader, XmlVersion};
use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, DateTime, ZipArchive, ZipWriter};

use crate::geometry::mesh::Mesh;

/// Where the model part lives in the package: the name the 3MF core specification uses and
/// slicers look for.
pub const MODEL_PART: &str = "3D/3dmodel.model";

/// Relationship type of the 3D model part (3MF core specification).
const MODEL_REL_TYPE: &str = "http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel";
/// XML namespace of the 3MF core model.
const CORE_NS: &str = "http://schemas.microsoft.com/3dmanufacturing/core/2015/02";

/// Default bed, mm (x, y). 200 × 200 fits inside every common consumer bed (Ender-3 class
/// 220 × 220, Prusa MK4 250 × 210, Bambu Lab 256 × 256), so a package laid out for it loads
/// without re-arranging on any of them.
pub const DEFAULT_BED_MM: [f64; 2] = [200.0, 200.0];

/// Default gap between laid-out parts, mm. 5 mm leaves room for a brim on each part and for
/// a nozzle travelling between them.
pub const DEFAULT_GAP_MM: f64 = 5.0;

/// The print bed a package is laid out for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bed {
    /// Usable size along x and y, mm; the bed spans [0, x] × [0, y].
    pub size_mm: [f64; 2],
    /// Gap between parts' bounding boxes, mm.
    pub gap_mm: f64,
}

impl Default for Bed {
    fn default() -> Self {
        Bed {
            size_mm: DEFAULT_BED_MM,
            gap_mm: DEFAULT_GAP_MM,
        }
    }
}

/// One part to write: a name (shown by slicers) and its mesh in mm, in the orientation it is
/// to be printed in (+z up).
#[derive(Clone, Copy, Debug)]
pub struct Part<'a> {
    /// Object name.
    pub name: &'a str,
    /// The mesh, mm.
    pub mesh: &'a Mesh,
}

/// Why parts do not fit the bed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum LayoutError {
    /// One part's footprint is larger than the bed.
    #[error(
        "part {name:?} is {:.1} × {:.1} mm, larger than the {:.1} × {:.1} mm bed",
        size[0], size[1], bed[0], bed[1]
    )]
    PartTooLarge {
        /// The part's name.
        name: String,
        /// Its footprint (x, y), mm.
        size: [f64; 2],
        /// The bed (x, y), mm.
        bed: [f64; 2],
    },
    /// The parts fit one by one but not together.
    #[error(
        "the parts need {:.1} × {:.1} mm laid out in rows with {gap:.1} mm gaps, more than \
         the {:.1} × {:.1} mm bed",
        needed[0], needed[1], bed[0], bed[1]
    )]
    BedTooSmall {
        /// Size the rows need (x, y), mm.
        needed: [f64; 2],
        /// The bed (x, y), mm.
        bed: [f64; 2],
        /// The gap used, mm.
        gap: f64,
    },
    /// A part has no vertices or a coordinate that is not finite.
    #[error("part {name:?} has no finite bounding box")]
    NoExtent {
        /// The part's name.
        name: String,
    },
}

/// Why a 3MF package could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum ThreeMfError {
    /// The file could not be created, written or read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The system's reason.
        source: std::io::Error,
    },
    /// The parts do not fit the bed.
    #[error("{path}: {source}")]
    Layout {
        /// The file.
        path: PathBuf,
        /// Why.
        source: LayoutError,
    },
    /// The package is not a 3MF we can read.
    #[error("{path}: {source}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        source: ThreeMfFormatError,
    },
}

/// What is wrong with a package (or the zip layer while writing one).
#[derive(Debug, thiserror::Error)]
pub enum ThreeMfFormatError {
    /// The zip layer failed.
    #[error("zip: {0}")]
    Zip(#[from] zip::result::ZipError),
    /// Writing a part of the package failed.
    #[error("writing the package: {0}")]
    Write(#[from] std::io::Error),
    /// A part the package needs is missing.
    #[error("the package has no part {0:?}")]
    MissingPart(String),
    /// `_rels/.rels` names no 3D model part.
    #[error("_rels/.rels has no relationship of type {MODEL_REL_TYPE}")]
    NoModelRelationship,
    /// A part is not well-formed XML or not UTF-8.
    #[error("{part} line {line}: {message}")]
    Xml {
        /// The package part.
        part: String,
        /// 1-based line.
        line: usize,
        /// What the parser or reader found.
        message: String,
    },
    /// An attribute is missing or its value cannot be used.
    #[error("{part} line {line}: {message}")]
    Attribute {
        /// The package part.
        part: String,
        /// 1-based line.
        line: usize,
        /// The element, the attribute and what is wrong with it.
        message: String,
    },
    /// Something the core specification allows but this reader does not handle.
    #[error("{part} line {line}: {what} is not supported by this reader")]
    Unsupported {
        /// The package part.
        part: String,
        /// 1-based line.
        line: usize,
        /// What was found.
        what: String,
    },
    /// A triangle refers to a vertex its object does not have.
    #[error(
        "object {object}: triangle {triangle} refers to vertex {vertex}, but it has {vertices}"
    )]
    BadIndex {
        /// The object's id.
        object: u32,
        /// Index of the triangle.
        triangle: usize,
        /// The index out of range.
        vertex: u32,
        /// Number of vertices of the object.
        vertices: usize,
    },
    /// A build item refers to an object the model does not define.
    #[error("build item {item} refers to object {object}, which the model does not define")]
    UnknownObject {
        /// Index of the item in the build.
        item: usize,
        /// The id it refers to.
        object: u32,
    },
}

/// An object of a model read back.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelObject {
    /// The object's id.
    pub id: u32,
    /// Its name, if it has one.
    pub name: Option<String>,
    /// Its mesh, in the model's unit.
    pub mesh: Mesh,
}

/// A build item: an object placed by an affine transform.
#[derive(Clone, Debug, PartialEq)]
pub struct BuildItem {
    /// The object's id.
    pub object_id: u32,
    /// The 3MF transform `m00 m01 m02 m10 m11 m12 m20 m21 m22 m30 m31 m32`, row-vector
    /// convention: a point p goes to (p, 1)·M, so m30..m32 is the translation.
    pub transform: [f64; 12],
}

impl BuildItem {
    /// Apply the transform to a point.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let m = &self.transform;
        std::array::from_fn(|k| p[0] * m[k] + p[1] * m[3 + k] + p[2] * m[6 + k] + m[9 + k])
    }
}

/// A 3MF package read back.
#[derive(Clone, Debug, PartialEq)]
pub struct ThreeMfModel {
    /// Name of the model part in the package (from `_rels/.rels`, without a leading `/`).
    pub model_part: String,
    /// The model's unit (`millimeter` when absent, as the specification says).
    pub unit: String,
    /// The objects in file order.
    pub objects: Vec<ModelObject>,
    /// The build items in file order.
    pub items: Vec<BuildItem>,
}

/// Place the parts' footprints on the bed: rows (shelves) filled left to right in order of
/// decreasing depth (y extent), `bed.gap_mm` between bounding boxes, the whole arrangement
/// centred on the bed, each part resting on z = 0. Returns each part's translation, in the
/// order given.
pub fn layout(parts: &[Part<'_>], bed: &Bed) -> Result<Vec<[f64; 3]>, LayoutError> {
    let mut boxes = Vec::with_capacity(parts.len());
    for p in parts {
        let b = p.mesh.aabb();
        let finite = b.min.iter().chain(&b.max).all(|x| x.is_finite());
        if p.mesh.vertices.is_empty() || !finite {
            return Err(LayoutError::NoExtent {
                name: p.name.to_string(),
            });
        }
        let size = b.size();
        if size[0] > bed.size_mm[0] || size[1] > bed.size_mm[1] {
            return Err(LayoutError::PartTooLarge {
                name: p.name.to_string(),
                size: [size[0], size[1]],
                bed: bed.size_mm,
            });
        }
        boxes.push(b);
    }
    let mut order: Vec<usize> = (0..parts.len()).collect();
    order.sort_by(|&a, &b| boxes[b].size()[1].total_cmp(&boxes[a].size()[1]));
    // Corner of each box on the bed before centring.
    let mut corner = vec![[0.0f64; 2]; parts.len()];
    let (mut x, mut y, mut shelf, mut width) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for &i in &order {
        let [w, d, _] = boxes[i].size();
        if x > 0.0 && x + w > bed.size_mm[0] {
            y += shelf + bed.gap_mm;
            x = 0.0;
            shelf = 0.0;
        }
        corner[i] = [x, y];
        width = width.max(x + w);
        shelf = shelf.max(d);
        x += w + bed.gap_mm;
    }
    let needed = [width, y + shelf];
    if needed[1] > bed.size_mm[1] {
        return Err(LayoutError::BedTooSmall {
            needed,
            bed: bed.size_mm,
            gap: bed.gap_mm,
        });
    }
    let margin = [
        0.5 * (bed.size_mm[0] - needed[0]),
        0.5 * (bed.size_mm[1] - needed[1]),
    ];
    Ok((0..parts.len())
        .map(|i| {
            [
                margin[0] + corner[i][0] - boxes[i].min[0],
                margin[1] + corner[i][1] - boxes[i].min[1],
                -boxes[i].min[2],
            ]
        })
        .collect())
}

/// Write the parts as a 3MF package at `path`, laid out on `bed` ([`layout`]). Returns each
/// part's translation on the bed.
pub fn write_3mf(
    path: &Path,
    parts: &[Part<'_>],
    bed: &Bed,
) -> Result<Vec<[f64; 3]>, ThreeMfError> {
    let offsets = layout(parts, bed).map_err(|source| ThreeMfError::Layout {
        path: path.to_path_buf(),
        source,
    })?;
    let file = File::create(path).map_err(|source| ThreeMfError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let placed: Vec<_> = parts.iter().copied().zip(offsets.iter().copied()).collect();
    write_package(BufWriter::new(file), &placed).map_err(|source| match source {
        ThreeMfFormatError::Write(source) => ThreeMfError::Io {
            path: path.to_path_buf(),
            source,
        },
        source => ThreeMfError::Format {
            path: path.to_path_buf(),
            source,
        },
    })?;
    Ok(offsets)
}

/// The bytes of a 3MF package of parts, each placed on the bed by a translation (mm).
pub fn threemf_bytes(placed: &[(Part<'_>, [f64; 3])]) -> Result<Vec<u8>, ThreeMfFormatError> {
    let mut buf = Cursor::new(Vec::new());
    write_package(&mut buf, placed)?;
    Ok(buf.into_inner())
}

/// Deflate level of the package's entries. 3: on the 0.4 mm parts of half-turn-2to1
/// (5.4 M triangles) the package took 3.8 s and 70.3 MB, against 9.3 s and 66.0 MB at the
/// library's default 6 and 2.4 s and 113 MB at 1; the model's XML is most of both.
const MODEL_DEFLATE_LEVEL: i64 = 3;

fn write_package<W: Write + Seek>(
    out: W,
    placed: &[(Part<'_>, [f64; 3])],
) -> Result<(), ThreeMfFormatError> {
    let mut zip = ZipWriter::new(out);
    let small = SimpleFileOptions::default()
        .compression_method(CompressionMethod::Deflated)
        .compression_level(Some(MODEL_DEFLATE_LEVEL))
        .last_modified_time(DateTime::default());
    zip.start_file("[Content_Types].xml", small)?;
    zip.write_all(CONTENT_TYPES.as_bytes())?;
    zip.start_file("_rels/.rels", small)?;
    zip.write_all(rels().as_bytes())?;
    // Model XML runs to ~110 bytes per triangle: past 4 GiB the entry needs Zip64.
    let estimate: u64 = placed
        .iter()
        .map(|(p, _)| 110 * p.mesh.triangles.len() as u64)
        .sum();
    zip.start_file(
        MODEL_PART,
        small.large_file(estimate >= u64::from(u32::MAX)),
    )?;
    {
        let mut w = BufWriter::with_capacity(1 << 20, &mut zip);
        write_model(&mut w, placed)?;
        w.flush()?;
    }
    zip.finish()?.flush()?;
    Ok(())
}

const CONTENT_TYPES: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">
 <Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/>
 <Default Extension="model" ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/>
</Types>
"#;

/// `_rels/.rels`: the one relationship, from the package to the model part.
fn rels() -> String {
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">
 <Relationship Target="/{MODEL_PART}" Id="rel0" Type="{MODEL_REL_TYPE}"/>
</Relationships>
"#
    )
}

fn write_model(w: &mut impl Write, placed: &[(Part<'_>, [f64; 3])]) -> std::io::Result<()> {
    writeln!(w, r#"<?xml version="1.0" encoding="UTF-8"?>"#)?;
    writeln!(
        w,
        r#"<model unit="millimeter" xml:lang="en-US" xmlns="{CORE_NS}">"#
    )?;
    writeln!(
        w,
        r#" <metadata name="Application">mpc-rig {}</metadata>"#,
        env!("CARGO_PKG_VERSION")
    )?;
    writeln!(w, " <resources>")?;
    for (i, (p, _)) in placed.iter().enumerate() {
        writeln!(
            w,
            r#"  <object id="{}" type="model" name="{}">"#,
            i + 1,
            escape(p.name)
        )?;
        writeln!(w, "   <mesh>\n    <vertices>")?;
        for v in &p.mesh.vertices {
            let [x, y, z] = v.map(|c| c as f32);
            writeln!(w, r#"     <vertex x="{x}" y="{y}" z="{z}"/>"#)?;
        }
        writeln!(w, "    </vertices>\n    <triangles>")?;
        for [a, b, c] in &p.mesh.triangles {
            writeln!(w, r#"     <triangle v1="{a}" v2="{b}" v3="{c}"/>"#)?;
        }
        writeln!(w, "    </triangles>\n   </mesh>\n  </object>")?;
    }
    writeln!(w, " </resources>\n <build>")?;
    for (i, (_, [x, y, z])) in placed.iter().enumerate() {
        writeln!(
            w,
            r#"  <item objectid="{}" transform="1 0 0 0 1 0 0 0 1 {x} {y} {z}"/>"#,
            i + 1
        )?;
    }
    writeln!(w, " </build>\n</model>")
}

/// Escape text for an XML attribute value.
fn escape(s: &str) -> Cow<'_, str> {
    if !s.contains(['&', '<', '>', '"', '\'']) {
        return Cow::Borrowed(s);
    }
    let mut out = String::with_capacity(s.len() + 8);
    for ch in s.chars() {
        match ch {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    Cow::Owned(out)
}

/// Read a 3MF package: follow `_rels/.rels` to the model part and read its objects and build
/// items (see the module doc for what is supported).
pub fn read_3mf(path: &Path) -> Result<ThreeMfModel, ThreeMfError> {
    let bytes = std::fs::read(path).map_err(|source| ThreeMfError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_3mf(&bytes).map_err(|source| ThreeMfError::Format {
        path: path.to_path_buf(),
        source,
    })
}

/// Parse the bytes of a 3MF package (see [`read_3mf`]).
pub fn parse_3mf(bytes: &[u8]) -> Result<ThreeMfModel, ThreeMfFormatError> {
    let mut zip = ZipArchive::new(Cursor::new(bytes))?;
    let rels = read_part(&mut zip, "_rels/.rels")?;
    let model_part = model_target(&rels)?;
    let xml = read_part(&mut zip, &model_part)?;
    let mut model = parse_model(&model_part, &xml)?;
    model.model_part = model_part;
    Ok(model)
}

fn read_part(
    zip: &mut ZipArchive<Cursor<&[u8]>>,
    name: &str,
) -> Result<String, ThreeMfFormatError> {
    let mut entry = match zip.by_name(name) {
        Ok(e) => e,
        Err(zip::result::ZipError::FileNotFound) => {
            return Err(ThreeMfFormatError::MissingPart(name.to_string()))
        }
        Err(e) => return Err(e.into()),
    };
    let mut s = String::new();
    entry
        .read_to_string(&mut s)
        .map_err(|e| ThreeMfFormatError::Xml {
            part: name.to_string(),
            line: 1,
            message: e.to_string(),
        })?;
    Ok(s)
}

/// 1-based line of byte offset `pos` in `text`.
fn line_at(text: &str, pos: u64) -> usize {
    let end = (pos as usize).min(text.len());
    1 + text.as_bytes()[..end]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
}

/// An XML cursor over one package part, with errors that name the part and line.
struct PartReader<'a> {
    part: &'a str,
    text: &'a str,
    reader: Reader<&'a [u8]>,
}

impl<'a> PartReader<'a> {
    fn new(part: &'a str, text: &'a str) -> Self {
        let mut reader = Reader::from_str(text);
        reader.config_mut().trim_text(true);
        PartReader { part, text, reader }
    }

    fn line(&self) -> usize {
        line_at(self.text, self.reader.buffer_position())
    }

    fn next(&mut self) -> Result<Event<'a>, ThreeMfFormatError> {
        self.reader
            .read_event()
            .map_err(|e| ThreeMfFormatError::Xml {
                part: self.part.to_string(),
                line: line_at(self.text, self.reader.error_position()),
                message: e.to_string(),
            })
    }

    /// The value of attribute `name` (local name) of `e`, if present.
    fn attr(&self, e: &BytesStart<'_>, name: &str) -> Result<Option<String>, ThreeMfFormatError> {
        for a in e.attributes() {
            let a = a.map_err(|err| self.xml_error(err.to_string()))?;
            if a.key.local_name().as_ref() == name.as_bytes() {
                let v = a
                    .decoded_and_normalized_value(XmlVersion::Implicit1_0, self.reader.decoder())
                    .map_err(|err| self.attr_error(e, name, err.to_string()))?;
                return Ok(Some(v.into_owned()));
            }
        }
        Ok(None)
    }

    /// Attribute `name` of `e`, required and parsed as `T`.
    fn parse<T: std::str::FromStr>(
        &self,
        e: &BytesStart<'_>,
        name: &str,
    ) -> Result<T, ThreeMfFormatError>
    where
        T::Err: std::fmt::Display,
    {
        let v = self
            .attr(e, name)?
            .ok_or_else(|| self.attr_error(e, name, "missing".into()))?;
        v.trim()
            .parse()
            .map_err(|err: T::Err| self.attr_error(e, name, format!("{v:?}: {err}")))
    }

    fn xml_error(&self, message: String) -> ThreeMfFormatError {
        ThreeMfFormatError::Xml {
            part: self.part.to_string(),
            line: self.line(),
            message,
        }
    }

    fn attr_error(&self, e: &BytesStart<'_>, name: &str, message: String) -> ThreeMfFormatError {
        ThreeMfFormatError::Attribute {
            part: self.part.to_string(),
            line: self.line(),
            message: format!(
                "<{}> attribute {name:?}: {message}",
                String::from_utf8_lossy(e.local_name().as_ref())
            ),
        }
    }
}

/// The model part named by the package relationships (leading `/` removed).
fn model_target(rels: &str) -> Result<String, ThreeMfFormatError> {
    let mut r = PartReader::new("_rels/.rels", rels);
    loop {
        match r.next()? {
            Event::Start(e) | Event::Empty(e)
                if e.local_name().as_ref() == b"Relationship"
                    && r.attr(&e, "Type")?.as_deref() == Some(MODEL_REL_TYPE) =>
            {
                let target: String = r.parse(&e, "Target")?;
                return Ok(target.trim_start_matches('/').to_string());
            }
            Event::Eof => return Err(ThreeMfFormatError::NoModelRelationship),
            _ => {}
        }
    }
}

fn parse_model(part: &str, xml: &str) -> Result<ThreeMfModel, ThreeMfFormatError> {
    let mut r = PartReader::new(part, xml);
    let mut model = ThreeMfModel {
        model_part: part.to_string(),
        unit: "millimeter".into(),
        objects: Vec::new(),
        items: Vec::new(),
    };
    let mut current: Option<ModelObject> = None;
    loop {
        let ev = r.next()?;
        let (e, empty) = match &ev {
            Event::Start(e) => (e, false),
            Event::Empty(e) => (e, true),
            Event::End(e) => {
                if e.local_name().as_ref() == b"object" {
                    if let Some(o) = current.take() {
                        model.objects.push(o);
                    }
                }
                continue;
            }
            Event::Eof => break,
            _ => continue,
        };
        match e.local_name().as_ref() {
            b"model" => {
                if let Some(u) = r.attr(e, "unit")? {
                    model.unit = u;
                }
            }
            b"object" => {
                let o = ModelObject {
                    id: r.parse(e, "id")?,
                    name: r.attr(e, "name")?,
                    mesh: Mesh::default(),
                };
                if empty {
                    model.objects.push(o);
                } else {
                    current = Some(o);
                }
            }
            b"components" | b"component" => {
                return Err(ThreeMfFormatError::Unsupported {
                    part: part.to_string(),
                    line: r.line(),
                    what: "an object made of components".into(),
                })
            }
            b"vertex" => {
                let v = [r.parse(e, "x")?, r.parse(e, "y")?, r.parse(e, "z")?];
                match current.as_mut() {
                    Some(o) => o.mesh.vertices.push(v),
                    None => return Err(r.xml_error("<vertex> outside an <object>".into())),
                }
            }
            b"triangle" => {
                let t = [r.parse(e, "v1")?, r.parse(e, "v2")?, r.parse(e, "v3")?];
                match current.as_mut() {
                    Some(o) => o.mesh.triangles.push(t),
                    None => return Err(r.xml_error("<triangle> outside an <object>".into())),
                }
            }
            b"item" => {
                let transform = match r.attr(e, "transform")? {
                    None => [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
                    Some(s) => {
                        let v: Result<Vec<f64>, _> = s.split_whitespace().map(str::parse).collect();
                        match v.ok().and_then(|v| <[f64; 12]>::try_from(v).ok()) {
                            Some(m) => m,
                            None => {
                                return Err(r.attr_error(
                                    e,
                                    "transform",
                                    format!("{s:?} is not 12 numbers"),
                                ))
                            }
                        }
                    }
                };
                model.items.push(BuildItem {
                    object_id: r.parse(e, "objectid")?,
                    transform,
                });
            }
            _ => {}
        }
    }
    for o in &model.objects {
        let nv = o.mesh.vertices.len();
        for (i, t) in o.mesh.triangles.iter().enumerate() {
            if let Some(&v) = t.iter().find(|&&v| v as usize >= nv) {
                return Err(ThreeMfFormatError::BadIndex {
                    object: o.id,
                    triangle: i,
                    vertex: v,
                    vertices: nv,
                });
            }
        }
    }
    for (i, item) in model.items.iter().enumerate() {
        if !model.objects.iter().any(|o| o.id == item.object_id) {
            return Err(ThreeMfFormatError::UnknownObject {
                item: i,
                object: item.object_id,
            });
        }
    }
    Ok(model)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::primitive_meshes::{cuboid, torus, uv_sphere};

    /// The two meshes have the same triangles over the same points rounded to f32 (the
    /// file's decimals are the shortest that read back to the written f32).
    fn assert_same_in_f32(a: &Mesh, b: &Mesh, what: &str) {
        assert_eq!(a.triangles, b.triangles, "{what}: triangles");
        assert_eq!(a.vertices.len(), b.vertices.len(), "{what}: vertex count");
        for (i, (p, q)) in a.vertices.iter().zip(&b.vertices).enumerate() {
            assert_eq!(
                p.map(|x| x as f32),
                q.map(|x| x as f32),
                "{what}: vertex {i}"
            );
        }
    }

    fn parts() -> Vec<(String, Mesh)> {
        vec![
            ("driver".into(), torus([3.0, -4.0, 7.0], 20.0, 6.0, 48, 16)),
            (
                "follower & <arm>".into(),
                uv_sphere([0.1, 0.2, 0.3], 15.0, 32, 16),
            ),
            (
                "support".into(),
                cuboid([-50.0, -20.0, -5.0], [30.0, 25.0, 0.0]),
            ),
        ]
    }

    /// The package has its model part at exactly `3D/3dmodel.model`, in millimetres, and
    /// reads back with every object's name and mesh equal to what was written (rounded to
    /// f32), one build item per part carrying the layout's translation.
    #[test]
    fn round_trip_equals_what_was_written() {
        let owned = parts();
        let ps: Vec<Part> = owned
            .iter()
            .map(|(n, m)| Part { name: n, mesh: m })
            .collect();
        let offsets = layout(&ps, &Bed::default()).unwrap();
        let placed: Vec<_> = ps.iter().copied().zip(offsets.iter().copied()).collect();
        let bytes = threemf_bytes(&placed).unwrap();
        let zip = ZipArchive::new(Cursor::new(&bytes[..])).unwrap();
        let names: Vec<&str> = zip.file_names().collect();
        assert!(names.contains(&"3D/3dmodel.model"), "{names:?}");
        assert!(names.contains(&"[Content_Types].xml") && names.contains(&"_rels/.rels"));
        drop(zip);
        let model = parse_3mf(&bytes).unwrap();
        assert_eq!(
            (model.model_part.as_str(), model.unit.as_str()),
            (MODEL_PART, "millimeter")
        );
        assert_eq!(model.objects.len(), 3);
        for (k, ((name, mesh), o)) in owned.iter().zip(&model.objects).enumerate() {
            assert_eq!(o.name.as_deref(), Some(name.as_str()));
            assert_same_in_f32(&o.mesh, mesh, name);
            let item = &model.items[k];
            assert_eq!(item.object_id, o.id);
            let t = [item.transform[9], item.transform[10], item.transform[11]];
            assert_eq!(t, offsets[k]);
        }
    }

    /// Every laid-out part lies on the bed (inside it, resting on z = 0) and no two
    /// footprints come closer than the gap, for a bed that needs two rows.
    #[test]
    fn layout_places_parts_apart_on_the_bed() {
        let owned = parts();
        let ps: Vec<Part> = owned
            .iter()
            .map(|(n, m)| Part { name: n, mesh: m })
            .collect();
        let bed = Bed {
            size_mm: [120.0, 120.0],
            gap_mm: 4.0,
        };
        let offsets = layout(&ps, &bed).unwrap();
        let placed: Vec<_> = ps
            .iter()
            .zip(&offsets)
            .map(|(p, o)| {
                let mut m = p.mesh.clone();
                m.translate(*o);
                m.aabb()
            })
            .collect();
        for b in &placed {
            assert!(b.min[0] >= 0.0 && b.min[1] >= 0.0, "{b:?}");
            assert!(b.max[0] <= 120.0 && b.max[1] <= 120.0, "{b:?}");
            assert!(b.min[2].abs() < 1e-12, "{b:?}");
        }
        // Two rows: the support (80 wide) and the torus (52) do not fit side by side.
        let rows: std::collections::BTreeSet<i64> =
            placed.iter().map(|b| b.min[1].round() as i64).collect();
        assert_eq!(rows.len(), 2, "{placed:?}");
        for i in 0..placed.len() {
            for j in i + 1..placed.len() {
                let (a, b) = (&placed[i], &placed[j]);
                let dx = (b.min[0] - a.max[0]).max(a.min[0] - b.max[0]);
                let dy = (b.min[1] - a.max[1]).max(a.min[1] - b.max[1]);
                assert!(dx.max(dy) >= 4.0 - 1e-9, "parts {i} and {j}: {a:?} {b:?}");
            }
        }
    }

    /// Parts that cannot fit are refused with the part or the size needed named.
    #[test]
    fn layout_refuses_what_does_not_fit() {
        let owned = parts();
        let ps: Vec<Part> = owned
            .iter()
            .map(|(n, m)| Part { name: n, mesh: m })
            .collect();
        let e = layout(
            &ps,
            &Bed {
                size_mm: [70.0, 200.0],
                gap_mm: 5.0,
            },
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .starts_with("part \"support\" is 80.0 × 45.0 mm, larger than the 70.0"),
            "{e}"
        );
        let e = layout(
            &ps,
            &Bed {
                size_mm: [90.0, 100.0],
                gap_mm: 5.0,
            },
        )
        .unwrap_err();
        assert!(matches!(e, LayoutError::BedTooSmall { .. }), "{e}");
        assert!(
            e.to_string().contains("more than the 90.0 × 100.0 mm bed"),
            "{e}"
        );
    }

    /// The same parts give the same bytes (fixed zip dates, deterministic layout).
    #[test]
    fn output_is_reproducible() {
        let owned = parts();
        let ps: Vec<Part> = owned
            .iter()
            .map(|(n, m)| Part { name: n, mesh: m })
            .collect();
        let offsets = layout(&ps, &Bed::default()).unwrap();
        let placed: Vec<_> = ps.iter().copied().zip(offsets).collect();
        assert_eq!(
            threemf_bytes(&placed).unwrap(),
            threemf_bytes(&placed).unwrap()
        );
    }

    /// Broken model XML is reported with the part and line; a triangle out of range and a
    /// build item naming no object are refused.
    #[test]
    fn malformed_models_are_named() {
        let model = |body: &str| {
            format!(
                "<?xml version=\"1.0\"?>\n<model xmlns=\"{CORE_NS}\">\n<resources>\n{body}\n</resources>\n</model>"
            )
        };
        let obj = "<object id=\"1\"><mesh><vertices>\n<vertex x=\"0\" y=\"0\" z=\"0\"/>\n\
                   <vertex x=\"1\" y=\"0\" z=\"0\"/><vertex x=\"0\" y=\"1\" z=\"0\"/></vertices>\n\
                   <triangles><triangle v1=\"0\" v2=\"1\" v3=\"TRI\"/></triangles></mesh></object>";
        let e = parse_model("3D/3dmodel.model", &model(&obj.replace("TRI", "two"))).unwrap_err();
        assert_eq!(
            e.to_string(),
            "3D/3dmodel.model line 7: <triangle> attribute \"v3\": \"two\": invalid digit found in string"
        );
        let e = parse_model("m", &model(&obj.replace("TRI", "3"))).unwrap_err();
        assert_eq!(
            e.to_string(),
            "object 1: triangle 0 refers to vertex 3, but it has 3"
        );
        let ok = model(&obj.replace("TRI", "2"));
        let with_item = ok.replace("</model>", "<build><item objectid=\"9\"/></build></model>");
        let e = parse_model("m", &with_item).unwrap_err();
        assert_eq!(
            e.to_string(),
            "build item 0 refers to object 9, which the model does not define"
        );
        let e = parse_model("m", "<model>\n<resources>\n<object id=\"1\">\n</model>").unwrap_err();
        assert!(e.to_string().starts_with("m line 4: "), "{e}");
    }
}
