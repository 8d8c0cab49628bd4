//! Lookup tables (Gunjee et al. §3, rendering-oriented attributes): a per-point integer
//! attribute (a LiDAR classification, a return number, or a file's scalar field such as a
//! material or segment id) indexes a table whose entries say how those points look: their
//! colour, opacity, splat size, Phong material, or that they are not shown at all. The paper
//! keeps colour, opacity, material ID, texture ID, size and physical values per point and
//! "defines a separate lookup table for some attributes"; here one table keyed by one
//! attribute sets any of them, and everything a table does not set keeps the cloud's own
//! value (its colours, opacities and radii, or the colour map of `--colour-by`).
//!
//! A table file (TOML):
//!
//! ```toml
//! key = "classification"          # classification, return, intensity, or a field's name
//!
//! [value.2]                       # the points whose key is 2
//! name = "ground"                 # for the report
//! colour = [150, 105, 60]         # sRGB, 0–255
//!
//! [value.9]
//! name = "water"
//! opacity = 0.4                   # 0–1
//! material = { specular = 0.9, shininess = 80 }
//!
//! [value.5]
//! size = 1.5                      # multiplies the splat radius (splat pipelines)
//!
//! [value.7]
//! show = false                    # noise: not drawn at all
//!
//! [default]                       # every value not listed (optional)
//! colour = [200, 200, 200]
//! ```
//!
//! Keys must be integers: values of a scalar field are rounded to the nearest integer when
//! they lie within 10⁻³ of it, and a field with other values is an error naming the first
//! such point. Points without a value (NaN: a merged cloud's points from a file without the
//! field) take the default entry.

use crate::PointCloud;
use serde::Deserialize;

/// The most entries a table may have (the materials it sets share the renderer's 256
/// object slots).
pub const MAX_ENTRIES: usize = 4096;

/// Phong terms an entry overrides (others keep the object's material).
#[derive(Clone, Copy, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialOverride {
    pub ambient: Option<f32>,
    pub diffuse: Option<f32>,
    pub specular: Option<f32>,
    pub shininess: Option<f32>,
}

impl MaterialOverride {
    pub fn is_empty(&self) -> bool {
        *self == MaterialOverride::default()
    }
}

/// How the points of one key value look; unset fields keep the points' own.
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Entry {
    /// A name for reports (e.g. "ground").
    pub name: Option<String>,
    /// sRGB colour (British or American spelling).
    #[serde(alias = "color")]
    pub colour: Option<[u8; 3]>,
    /// Opacity in [0, 1].
    pub opacity: Option<f32>,
    /// Factor on the splat radius (splat pipelines; the point pipelines draw one pixel per
    /// point).
    pub size: Option<f32>,
    /// false: the points are left out.
    pub show: Option<bool>,
    #[serde(default)]
    pub material: MaterialOverride,
}

/// A lookup table as its file gives it.
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LookupTable {
    /// The attribute whose integer value indexes the table.
    pub key: String,
    /// Entries by value (TOML keys are strings: `[value.2]`).
    #[serde(default)]
    pub value: std::collections::BTreeMap<String, Entry>,
    /// For values not listed.
    #[serde(default)]
    pub default: Entry,
}

/// Why a table cannot be used on a cloud.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LookupError {
    #[error("{0}")]
    Table(String),
    #[error("the cloud has no `{key}` to look up (it has: {have})")]
    NoKey { key: String, have: String },
    #[error("point {index} has {key} = {value}, not an integer: a lookup table's key must be")]
    NotInteger {
        key: String,
        index: usize,
        value: f64,
    },
    #[error("the table hides every point")]
    NothingShown,
}

/// What applying a table did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Applied {
    /// Per point kept (in the order kept): the index + 1 of the table's material override it
    /// takes, or 0 for none. Empty when the table sets no material.
    pub material_slot: Vec<u8>,
    /// The overrides that slots 1, 2, … stand for.
    pub overrides: Vec<MaterialOverride>,
    /// Per point of the cloud as it was: kept or not. Empty when every point is kept.
    pub kept: Vec<bool>,
    /// Points per entry: (the value, or None for the default entry; its name; points).
    pub counts: Vec<(Option<i64>, Option<String>, usize)>,
}

impl LookupTable {
    /// Checks the entries' values and turns the keys into integers.
    fn entries(&self) -> Result<Vec<(i64, &Entry)>, LookupError> {
        if self.value.len() > MAX_ENTRIES {
            return Err(LookupError::Table(format!(
                "{} entries; a table holds at most {MAX_ENTRIES}",
                self.value.len()
            )));
        }
        let mut v = Vec::with_capacity(self.value.len());
        for (k, e) in &self.value {
            let key: i64 = k.trim().parse().map_err(|_| {
                LookupError::Table(format!("`[value.{k}]`: the key must be an integer"))
            })?;
            check_entry(e).map_err(|m| LookupError::Table(format!("`[value.{k}]`: {m}")))?;
            v.push((key, e));
        }
        check_entry(&self.default).map_err(|m| LookupError::Table(format!("`[default]`: {m}")))?;
        v.sort_by_key(|&(k, _)| k);
        if let Some(w) = v.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(LookupError::Table(format!(
                "the value {} is listed twice",
                w[0].0
            )));
        }
        Ok(v)
    }

    /// Checks the table on its own (its keys are integers, its values in range).
    pub fn validate(&self) -> Result<(), LookupError> {
        if self.key.trim().is_empty() {
            return Err(LookupError::Table(
                "`key` is empty: name the attribute to look up".into(),
            ));
        }
        self.entries().map(|_| ())
    }
}

fn check_entry(e: &Entry) -> Result<(), String> {
    if let Some(o) = e.opacity {
        if !(0.0..=1.0).contains(&o) {
            return Err(format!("opacity {o}: it must lie in 0..1"));
        }
    }
    if let Some(s) = e.size {
        if !(s.is_finite() && s > 0.0 && s <= 1e3) {
            return Err(format!("size {s}: a factor above 0 and at most 1000"));
        }
    }
    let m = &e.material;
    for (name, v, hi) in [
        ("ambient", m.ambient, 10.0),
        ("diffuse", m.diffuse, 10.0),
        ("specular", m.specular, 10.0),
        ("shininess", m.shininess, 4096.0),
    ] {
        if let Some(v) = v {
            if !(v.is_finite() && (0.0..=hi).contains(&v)) {
                return Err(format!("material {name} = {v}: it must lie in 0..{hi}"));
            }
        }
    }
    Ok(())
}

/// The value of `key` per point: a built-in attribute (classification, return, intensity)
/// or a scalar field of that name.
fn key_values(cloud: &PointCloud, key: &str) -> Result<Vec<f64>, LookupError> {
    let k = key.trim();
    let col = |v: Option<Vec<f64>>| v;
    let v = if k.eq_ignore_ascii_case("classification") || k.eq_ignore_ascii_case("class") {
        col(cloud
            .classification
            .as_ref()
            .map(|c| c.iter().map(|&x| x as f64).collect()))
    } else if k.eq_ignore_ascii_case("return") || k.eq_ignore_ascii_case("return-number") {
        col(cloud
            .return_number
            .as_ref()
            .map(|c| c.iter().map(|&x| x as f64).collect()))
    } else if k.eq_ignore_ascii_case("intensity") {
        col(cloud
            .intensity
            .as_ref()
            .map(|c| c.iter().map(|&x| x as f64).collect()))
    } else {
        None
    };
    if let Some(v) = v {
        return Ok(v);
    }
    match cloud.field(k) {
        Some(f) => Ok((0..cloud.len()).map(|i| f.value(i)).collect()),
        None => Err(LookupError::NoKey {
            key: k.to_string(),
            have: cloud.attributes().join(", "),
        }),
    }
}

/// Applies `table` to `cloud`: colours (points of entries without one keep theirs, or
/// `fallback` when the cloud had none), opacities, radius factors (into `size`, one per kept
/// point, when some entry sets one), and leaves out the points of hidden entries (every
/// column, faces touching them included).
pub fn apply(
    cloud: &mut PointCloud,
    table: &LookupTable,
    fallback: [u8; 3],
    size: &mut Option<Vec<f32>>,
) -> Result<Applied, LookupError> {
    table.validate()?;
    let entries = table.entries()?;
    let values = key_values(cloud, &table.key)?;
    let n = cloud.len();
    // The entry of every point: its index in `entries`, or entries.len() for the default.
    let def = entries.len();
    let mut which = Vec::with_capacity(n);
    for (i, &v) in values.iter().enumerate() {
        if v.is_nan() {
            which.push(def as u32);
            continue;
        }
        let r = v.round();
        if (v - r).abs() > 1e-3 || !r.is_finite() || r.abs() > 9.0e15 {
            return Err(LookupError::NotInteger {
                key: table.key.trim().to_string(),
                index: i,
                value: v,
            });
        }
        let r = r as i64;
        which.push(entries.binary_search_by_key(&r, |&(k, _)| k).unwrap_or(def) as u32);
    }
    let entry = |w: u32| -> &Entry {
        if w as usize == def {
            &table.default
        } else {
            entries[w as usize].1
        }
    };
    let mut counts = vec![0usize; def + 1];
    for &w in &which {
        counts[w as usize] += 1;
    }
    let mut out = Applied {
        counts: (0..=def)
            .filter(|&w| counts[w] > 0)
            .map(|w| {
                let e = entry(w as u32);
                let v = (w != def).then(|| entries[w].0);
                (v, e.name.clone(), counts[w])
            })
            .collect(),
        ..Applied::default()
    };
    // Colours, opacities and sizes, on every point first; hidden points go last.
    let all = entries.iter().map(|e| e.1).chain([&table.default]);
    let (any_colour, any_opacity, any_size, any_hidden) =
        all.fold((false, false, false, false), |(c, o, s, h), e| {
            (
                c || e.colour.is_some(),
                o || e.opacity.is_some(),
                s || e.size.is_some(),
                h || e.show == Some(false),
            )
        });
    if any_colour {
        let mut col = cloud.colors.take().unwrap_or_else(|| vec![fallback; n]);
        for (c, &w) in col.iter_mut().zip(&which) {
            if let Some(x) = entry(w).colour {
                *c = x;
            }
        }
        cloud.colors = Some(col);
    }
    if any_opacity {
        let mut op = cloud.opacity.take().unwrap_or_else(|| vec![1.0; n]);
        for (o, &w) in op.iter_mut().zip(&which) {
            if let Some(x) = entry(w).opacity {
                *o = x;
            }
        }
        cloud.opacity = Some(op);
    }
    if any_size {
        let mut s = size.take().filter(|s| s.len() == n).unwrap_or(vec![1.0; n]);
        for (s, &w) in s.iter_mut().zip(&which) {
            if let Some(x) = entry(w).size {
                *s *= x;
            }
        }
        *size = Some(s);
    }
    // Materials: one slot per distinct override.
    let mut slot_of = vec![0u8; def + 1];
    for w in 0..=def {
        let m = entry(w as u32).material;
        if m.is_empty() || counts[w] == 0 {
            continue;
        }
        let k = match out.overrides.iter().position(|&o| o == m) {
            Some(k) => k,
            None => {
                if out.overrides.len() >= 255 {
                    return Err(LookupError::Table(
                        "more than 255 different materials are in use".into(),
                    ));
                }
                out.overrides.push(m);
                out.overrides.len() - 1
            }
        };
        slot_of[w] = (k + 1) as u8;
    }
    if !out.overrides.is_empty() {
        out.material_slot = which.iter().map(|&w| slot_of[w as usize]).collect();
    }
    if any_hidden {
        let kept: Vec<bool> = which
            .iter()
            .map(|&w| entry(w).show != Some(false))
            .collect();
        if !kept.iter().any(|&k| k) {
            return Err(LookupError::NothingShown);
        }
        cloud.retain(&kept);
        if let Some(s) = size.as_mut() {
            retain(s, &kept);
        }
        if !out.material_slot.is_empty() {
            retain(&mut out.material_slot, &kept);
        }
        out.kept = kept;
    }
    Ok(out)
}

/// What a lookup table did, in one line: points per entry (the largest first), hidden ones.
pub fn summary(path: &std::path::Path, table: &LookupTable, a: &Applied) -> String {
    let mut counts = a.counts.clone();
    counts.sort_by_key(|c| std::cmp::Reverse(c.2));
    let shown: Vec<String> = counts
        .iter()
        .take(8)
        .map(|(v, name, n)| {
            let v = v.map_or("other".to_string(), |v| v.to_string());
            match name {
                Some(name) => format!("{v} {name} {n}"),
                None => format!("{v} {n}"),
            }
        })
        .collect();
    let more = counts.len().saturating_sub(8);
    let hidden = a.kept.iter().filter(|&&k| !k).count();
    format!(
        "lookup {} by {}: {}{}{}",
        path.display(),
        table.key.trim(),
        shown.join(", "),
        if more > 0 {
            format!(" and {more} more values")
        } else {
            String::new()
        },
        if hidden > 0 {
            format!("; {hidden} points hidden")
        } else {
            String::new()
        }
    )
}

/// Keeps the elements whose flag is set.
pub fn retain<T>(v: &mut Vec<T>, keep: &[bool]) {
    let mut k = keep.iter();
    v.retain(|_| *k.next().unwrap_or(&true));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloud::Field;
    use glam::Vec3;

    fn cloud() -> PointCloud {
        let mut c =
            PointCloud::from_positions((0..6).map(|i| Vec3::new(i as f32, 0.0, 0.0)).collect());
        c.classification = Some(vec![2, 2, 5, 7, 9, 1]);
        c.faces = vec![[0, 1, 2], [2, 3, 4]];
        c
    }

    fn table(text: &str) -> LookupTable {
        // A hand-built table (the TOML reader lives in stipple-io).
        serde_json::from_str(text).unwrap()
    }

    #[test]
    fn entries_set_what_they_name_and_hidden_points_go() {
        let mut c = cloud();
        c.colors = Some(vec![[1, 1, 1]; 6]);
        let t = table(
            r#"{"key": "classification",
                "value": {"2": {"name": "ground", "colour": [150, 105, 60]},
                          "7": {"show": false},
                          "9": {"opacity": 0.25, "material": {"specular": 0.9}},
                          "5": {"size": 2.0}}}"#,
        );
        let mut size = None;
        let a = apply(&mut c, &t, [9, 9, 9], &mut size).unwrap();
        assert_eq!(c.len(), 5);
        assert_eq!(a.kept, vec![true, true, true, false, true, true]);
        assert_eq!(
            c.colors.as_ref().unwrap(),
            &vec![
                [150, 105, 60],
                [150, 105, 60],
                [1, 1, 1],
                [1, 1, 1],
                [1, 1, 1]
            ]
        );
        assert_eq!(c.opacity.as_ref().unwrap(), &vec![1.0, 1.0, 1.0, 0.25, 1.0]);
        assert_eq!(size.unwrap(), vec![1.0, 1.0, 2.0, 1.0, 1.0]);
        assert_eq!(a.material_slot, vec![0, 0, 0, 1, 0]);
        assert_eq!(a.overrides[0].specular, Some(0.9));
        // The face through the hidden point is gone, the other re-indexed.
        assert_eq!(c.faces, vec![[0, 1, 2]]);
        assert_eq!(c.classification.as_ref().unwrap(), &vec![2, 2, 5, 9, 1]);
        let ground = a.counts.iter().find(|e| e.0 == Some(2)).unwrap();
        assert_eq!((ground.1.as_deref(), ground.2), (Some("ground"), 2));
        // Unlisted values (1) took the default entry.
        assert!(a.counts.iter().any(|e| e.0.is_none() && e.2 == 1));
    }

    #[test]
    fn fields_are_keys_and_must_be_integers() {
        let mut c = cloud();
        c.fields.push(Field::new(
            "scalar_Material",
            &[3.0, 3.0, 4.0, f64::NAN, 4.0, 3.0],
        ));
        let t = table(
            r#"{"key": "material", "value": {"4": {"colour": [0, 255, 0]}}, "default": {"colour": [255, 0, 0]}}"#,
        );
        apply(&mut c, &t, [0, 0, 0], &mut None).unwrap();
        let col = c.colors.unwrap();
        assert_eq!(col[2], [0, 255, 0]);
        assert_eq!(col[0], [255, 0, 0]);
        assert_eq!(col[3], [255, 0, 0], "no value: the default entry");
        let mut c = cloud();
        c.fields.push(Field::new("w", &[0.5; 6]));
        let t = table(r#"{"key": "w"}"#);
        assert!(matches!(
            apply(&mut c, &t, [0; 3], &mut None),
            Err(LookupError::NotInteger { index: 0, .. })
        ));
        let e = apply(
            &mut cloud(),
            &table(r#"{"key": "segment"}"#),
            [0; 3],
            &mut None,
        );
        assert!(e.unwrap_err().to_string().contains("classification"));
    }

    #[test]
    fn bad_tables_are_errors() {
        for (t, want) in [
            (r#"{"key": "class", "value": {"x": {}}}"#, "integer"),
            (
                r#"{"key": "class", "value": {"2": {"opacity": 2}}}"#,
                "opacity",
            ),
            (r#"{"key": "class", "value": {"2": {"size": 0}}}"#, "size"),
            (r#"{"key": "class", "value": {"2": {}, "02": {}}}"#, "twice"),
            (
                r#"{"key": "class", "default": {"material": {"shininess": -1}}}"#,
                "shininess",
            ),
            (r#"{"key": " "}"#, "empty"),
        ] {
            let e = apply(&mut cloud(), &table(t), [0; 3], &mut None).unwrap_err();
            assert!(e.to_string().contains(want), "{t}: {e}");
        }
        let t = table(r#"{"key": "class", "default": {"show": false}}"#);
        assert_eq!(
            apply(&mut cloud(), &t, [0; 3], &mut None),
            Err(LookupError::NothingShown)
        );
    }
}
