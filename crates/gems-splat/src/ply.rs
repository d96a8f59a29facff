//! Inria-layout 3DGS PLY files (as written by the original 3DGS code, gsplat and Brush, and read
//! by common splat viewers).
//!
//! One `vertex` element with float properties `x y z`, optional `nx ny nz` (written as zeros),
//! `f_dc_0..2` (SH degree 0), `f_rest_*` (the higher SH coefficients, channel-major: all of red,
//! then green, then blue), `opacity` (logit), `scale_0..2` (log) and `rot_0..3` (wxyz, as stored).
//! The SH degree is inferred from the number of `f_rest_*` properties (0, 9, 24 or 45).
//! Writing is binary little-endian and atomic (temporary file in the same directory + rename).

use std::fmt;
use std::io::BufReader;
use std::path::Path;

use serde::de::{self, Deserializer, IgnoredAny, MapAccess, Visitor};
use serde::ser::{SerializeMap, Serializer};
use serde::{Deserialize, Serialize};

use crate::{Gaussians, SH_COEFFS, SplatError};

const SLOT_XYZ: usize = 0;
const SLOT_NORMAL: usize = 3;
const SLOT_DC: usize = 6;
const SLOT_REST: usize = 9;
const MAX_REST: usize = (SH_COEFFS - 1) * 3;
const SLOT_OPACITY: usize = SLOT_REST + MAX_REST;
const SLOT_SCALE: usize = SLOT_OPACITY + 1;
const SLOT_ROT: usize = SLOT_SCALE + 3;
const SLOTS: usize = SLOT_ROT + 4;

/// Property name of each slot.
fn slot_name(slot: usize) -> String {
    match slot {
        0..3 => ["x", "y", "z"][slot].to_owned(),
        3..6 => ["nx", "ny", "nz"][slot - SLOT_NORMAL].to_owned(),
        6..9 => format!("f_dc_{}", slot - SLOT_DC),
        SLOT_OPACITY => "opacity".to_owned(),
        s if (SLOT_REST..SLOT_OPACITY).contains(&s) => format!("f_rest_{}", s - SLOT_REST),
        s if (SLOT_SCALE..SLOT_ROT).contains(&s) => format!("scale_{}", s - SLOT_SCALE),
        s => format!("rot_{}", s - SLOT_ROT),
    }
}

fn slot_of(name: &str) -> Option<usize> {
    let idx = |prefix: &str, len: usize| {
        name.strip_prefix(prefix)
            .and_then(|r| r.parse::<usize>().ok())
            .filter(|&i| i < len && (i == 0 || !name[prefix.len()..].starts_with('0')))
    };
    Some(match name {
        "x" => 0,
        "y" => 1,
        "z" => 2,
        "nx" => 3,
        "ny" => 4,
        "nz" => 5,
        "opacity" => SLOT_OPACITY,
        _ => {
            if let Some(i) = idx("f_dc_", 3) {
                SLOT_DC + i
            } else if let Some(i) = idx("f_rest_", MAX_REST) {
                SLOT_REST + i
            } else if let Some(i) = idx("scale_", 3) {
                SLOT_SCALE + i
            } else if let Some(i) = idx("rot_", 4) {
                SLOT_ROT + i
            } else {
                return None;
            }
        }
    })
}

/// One vertex row: the known properties by slot and which of them were present.
struct Row {
    vals: [f32; SLOTS],
    present: u64,
}

impl<'de> Deserialize<'de> for Row {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct RowVisitor;
        struct Key(Option<usize>);
        impl<'de> Deserialize<'de> for Key {
            fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                struct KeyVisitor;
                impl Visitor<'_> for KeyVisitor {
                    type Value = Key;
                    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                        f.write_str("a property name")
                    }
                    fn visit_str<E: de::Error>(self, v: &str) -> Result<Key, E> {
                        Ok(Key(slot_of(v)))
                    }
                    fn visit_bytes<E: de::Error>(self, v: &[u8]) -> Result<Key, E> {
                        Ok(Key(std::str::from_utf8(v).ok().and_then(slot_of)))
                    }
                }
                d.deserialize_str(KeyVisitor)
            }
        }
        impl<'de> Visitor<'de> for RowVisitor {
            type Value = Row;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a vertex row")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Row, A::Error> {
                let mut row = Row {
                    vals: [0.0; SLOTS],
                    present: 0,
                };
                while let Some(Key(slot)) = map.next_key::<Key>()? {
                    match slot {
                        Some(s) => {
                            row.vals[s] = map.next_value::<f32>()?;
                            row.present |= 1 << s;
                        }
                        None => {
                            map.next_value::<IgnoredAny>()?;
                        }
                    }
                }
                Ok(row)
            }
        }
        d.deserialize_map(RowVisitor)
    }
}

#[derive(Deserialize)]
struct PlyIn {
    vertex: Vec<Row>,
}

/// Reads an Inria-layout PLY file.
pub fn read_ply(path: impl AsRef<Path>) -> Result<Gaussians, SplatError> {
    let path = path.as_ref();
    let err = |reason: String| SplatError::Ply {
        path: path.to_path_buf(),
        reason,
    };
    let file = std::fs::File::open(path).map_err(|e| err(e.to_string()))?;
    let parsed: PlyIn =
        serde_ply::from_reader(BufReader::new(file)).map_err(|e| err(e.to_string()))?;
    let rows = parsed.vertex;
    let Some(first) = rows.first() else {
        return Ok(Gaussians::with_degree(0));
    };
    let present = first.present;
    if let Some(r) = rows.iter().find(|r| r.present != present) {
        return Err(err(format!(
            "vertex rows have different properties ({:#x} vs {:#x})",
            r.present, present
        )));
    }
    let required = (0..3)
        .chain(SLOT_DC..SLOT_DC + 3)
        .chain([SLOT_OPACITY])
        .chain(SLOT_SCALE..SLOT_SCALE + 3)
        .chain(SLOT_ROT..SLOT_ROT + 4);
    for s in required {
        if present & (1 << s) == 0 {
            return Err(err(format!(
                "missing vertex property `{}` (not an Inria-layout splat file?)",
                slot_name(s)
            )));
        }
    }
    let rest = (SLOT_REST..SLOT_OPACITY)
        .filter(|&s| present & (1 << s) != 0)
        .count();
    let degree = match rest {
        0 => 0,
        9 => 1,
        24 => 2,
        45 => 3,
        k => {
            return Err(err(format!(
                "{k} f_rest_* properties; expected 0, 9, 24 or 45 (SH degree 0-3)"
            )));
        }
    };
    if (SLOT_REST..SLOT_REST + rest).any(|s| present & (1 << s) == 0) {
        return Err(err(format!(
            "f_rest_* properties are not f_rest_0..f_rest_{}",
            rest - 1
        )));
    }
    let per_channel = rest / 3;
    let mut g = Gaussians::with_degree(degree);
    for r in &rows {
        let v = &r.vals;
        let mut sh = [[0.0f32; 3]; SH_COEFFS];
        sh[0] = [v[SLOT_DC], v[SLOT_DC + 1], v[SLOT_DC + 2]];
        for k in 1..=per_channel {
            for (ch, value) in sh[k].iter_mut().enumerate() {
                *value = v[SLOT_REST + ch * per_channel + k - 1];
            }
        }
        g.push(
            [v[SLOT_XYZ], v[SLOT_XYZ + 1], v[SLOT_XYZ + 2]],
            [
                v[SLOT_ROT],
                v[SLOT_ROT + 1],
                v[SLOT_ROT + 2],
                v[SLOT_ROT + 3],
            ],
            [v[SLOT_SCALE], v[SLOT_SCALE + 1], v[SLOT_SCALE + 2]],
            v[SLOT_OPACITY],
            sh,
        );
    }
    Ok(g)
}

/// Rows for writing: slot order, with the f_rest count of the scene's degree.
struct RowOut<'a> {
    g: &'a Gaussians,
    i: usize,
    names: &'a [String],
    slots: &'a [usize],
}

impl Serialize for RowOut<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let (g, i) = (self.g, self.i);
        let per_channel = crate::sh::num_coeffs(g.sh_degree) - 1;
        let mut map = s.serialize_map(Some(self.slots.len()))?;
        for (name, &slot) in self.names.iter().zip(self.slots) {
            let v = match slot {
                0..3 => g.means[i][slot],
                3..6 => 0.0,
                6..9 => g.sh[i][0][slot - SLOT_DC],
                SLOT_OPACITY => g.opacity_logits[i],
                s if (SLOT_REST..SLOT_OPACITY).contains(&s) => {
                    let r = s - SLOT_REST;
                    let (ch, k) = (r / per_channel, r % per_channel + 1);
                    g.sh[i][k][ch]
                }
                s if (SLOT_SCALE..SLOT_ROT).contains(&s) => g.log_scales[i][s - SLOT_SCALE],
                s => g.quats[i][s - SLOT_ROT],
            };
            map.serialize_entry(name.as_str(), &v)?;
        }
        map.end()
    }
}

struct Rows<'a> {
    g: &'a Gaussians,
    names: Vec<String>,
    slots: Vec<usize>,
}

impl Serialize for Rows<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq((0..self.g.len()).map(|i| RowOut {
            g: self.g,
            i,
            names: &self.names,
            slots: &self.slots,
        }))
    }
}

#[derive(Serialize)]
struct PlyOut<'a> {
    vertex: Rows<'a>,
}

/// Writes `g` as a binary little-endian Inria-layout PLY, atomically.
pub fn write_ply(path: impl AsRef<Path>, g: &Gaussians) -> Result<(), SplatError> {
    let path = path.as_ref();
    let err = |reason: String| SplatError::Ply {
        path: path.to_path_buf(),
        reason,
    };
    g.validate().map_err(|e| err(e.to_string()))?;
    let rest = (crate::sh::num_coeffs(g.sh_degree) - 1) * 3;
    let slots: Vec<usize> = (0..SLOT_REST + rest).chain(SLOT_OPACITY..SLOTS).collect();
    let names = slots.iter().map(|&s| slot_name(s)).collect();
    let out = PlyOut {
        vertex: Rows { g, names, slots },
    };
    gems_fs::write_atomic_with(path, |w| {
        serde_ply::to_writer(&out, serde_ply::SerializeOptions::binary_le(), w)
            .map_err(std::io::Error::other)
    })
    .map_err(|e| SplatError::Ply {
        path: e.path,
        reason: e.source.to_string(),
    })
}
