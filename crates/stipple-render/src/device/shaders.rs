//! WGSL sources. Each pass has its shader of the same name in its folder (`src/passes/NAME/`),
//! shared snippets are in `src/shaders/`; a module is the
//! shared `common.wgsl` followed by the files the pass needs (WGSL has no includes).

const COMMON: &str = include_str!("../shaders/common.wgsl");
/// The bindings every pixel pass shares (see `crate::passes::pixel`).
pub const PIXEL_PASS: &str = include_str!("../shaders/pixel_pass.wgsl");
const POINT_PROJECTION: &str = include_str!("../shaders/point_projection.wgsl");
const PROJECT: &str = include_str!("../passes/project/project.wgsl");
const PROJECT_ATOMIC64: &str = include_str!("../passes/project/project_atomic64.wgsl");
const PROJECT_ATOMIC32: &str = include_str!("../passes/project/project_atomic32.wgsl");
const PROJECT_HW: &str = include_str!("../passes/project/project_hw.wgsl");
const RESOLVE: &str = include_str!("../passes/project/resolve.wgsl");
const PEEL_REFERENCE: &str = include_str!("../passes/project/peel_reference.wgsl");
const FILL: &str = include_str!("../passes/fill/fill.wgsl");
const FILL_BACKGROUND: &str = include_str!("../passes/fill_background/fill_background.wgsl");
const FILL_OCCLUDED: &str = include_str!("../passes/fill_occluded/fill_occluded.wgsl");
const FILL_PLANES: &str = include_str!("../passes/fill_occluded/fill_planes.wgsl");
const ITERATE: &str = include_str!("iterate.wgsl");
const GATHER: &str = include_str!("../passes/shade/gather.wgsl");
const SHADE: &str = include_str!("../passes/shade/shade.wgsl");
const WEIGHTED: &str = include_str!("../shaders/weighted.wgsl");
const SMOOTH: &str = include_str!("../passes/smooth/smooth.wgsl");
const ANTIALIAS: &str = include_str!("../passes/antialias/antialias.wgsl");
const OUTPUT: &str = include_str!("../passes/output/output.wgsl");
const SCREEN: &str = include_str!("../shaders/screen.wgsl");
const VISIBILITY: &str = include_str!("../passes/visibility/visibility.wgsl");
const FILL_ANISOTROPIC: &str = include_str!("../passes/fill_anisotropic/fill_anisotropic.wgsl");
const DEPICTION: &str = include_str!("../passes/depiction/depiction.wgsl");
const DEPICTION_APPLY: &str = include_str!("../passes/depiction/depiction_apply.wgsl");
const EDL: &str = include_str!("../passes/edl/edl.wgsl");
const BLEND_LAYERS: &str = include_str!("../passes/blend_layers/blend_layers.wgsl");
const SHADOW_TEXTURE: &str = include_str!("../passes/shadow_texture/shadow_texture.wgsl");
const SPLAT: &str = include_str!("../passes/splat/splat.wgsl");
const BUCKET_SORT: &str = include_str!("../passes/bucket_sort/bucket_sort.wgsl");
const SORTED: &str = include_str!("../passes/splat/sorted.wgsl");

/// A shader module: its name and the files it is made of (after `common.wgsl`).
#[derive(Clone, Copy, Debug)]
pub struct ShaderModule {
    pub name: &'static str,
    parts: &'static [&'static str],
    /// Needs 64-bit integer atomics (SHADER_INT64 + SHADER_INT64_ATOMIC_MIN_MAX).
    pub int64: bool,
}

impl ShaderModule {
    /// A module made of `common.wgsl` and `parts` (no 64-bit atomics).
    pub const fn new(name: &'static str, parts: &'static [&'static str]) -> ShaderModule {
        ShaderModule {
            name,
            parts,
            int64: false,
        }
    }

    pub fn source(&self) -> String {
        let mut s = String::from(COMMON);
        for p in self.parts {
            s.push('\n');
            s.push_str(p);
        }
        s
    }
}

pub const PROJECT64: ShaderModule = ShaderModule {
    name: "project (64-bit atomics)",
    parts: &[PROJECT, POINT_PROJECTION, PROJECT_ATOMIC64],
    int64: true,
};
pub const PROJECT32: ShaderModule = ShaderModule {
    name: "project (32-bit fallback)",
    parts: &[PROJECT, POINT_PROJECTION, PROJECT_ATOMIC32],
    int64: false,
};
pub const PROJECT_HW_MODULE: ShaderModule = ShaderModule {
    name: "project_hw",
    parts: &[PROJECT_HW],
    int64: false,
};
pub const PEEL_REFERENCE_MODULE: ShaderModule = ShaderModule {
    name: "peel_reference",
    parts: &[PEEL_REFERENCE],
    int64: false,
};
pub const RESOLVE_MODULE: ShaderModule = ShaderModule {
    name: "resolve",
    parts: &[RESOLVE],
    int64: false,
};
pub const FILL_BACKGROUND_MODULE: ShaderModule = ShaderModule {
    name: "fill_background",
    parts: &[FILL, FILL_BACKGROUND],
    int64: false,
};
pub const FILL_OCCLUDED_MODULE: ShaderModule = ShaderModule {
    name: "fill_occluded",
    parts: &[FILL, FILL_OCCLUDED],
    int64: false,
};
pub const FILL_PLANES_MODULE: ShaderModule = ShaderModule {
    name: "fill_planes",
    parts: &[FILL_PLANES],
    int64: false,
};
pub const ITERATE_MODULE: ShaderModule = ShaderModule {
    name: "iterate",
    parts: &[ITERATE],
    int64: false,
};
pub const GATHER_MODULE: ShaderModule = ShaderModule {
    name: "gather",
    parts: &[GATHER],
    int64: false,
};
pub const SHADE_MODULE: ShaderModule = ShaderModule {
    name: "shade",
    parts: &[SHADE],
    int64: false,
};
pub const SMOOTH_MODULE: ShaderModule = ShaderModule {
    name: "smooth",
    parts: &[SMOOTH, WEIGHTED],
    int64: false,
};
pub const ANTIALIAS_MODULE: ShaderModule = ShaderModule {
    name: "antialias",
    parts: &[ANTIALIAS, WEIGHTED],
    int64: false,
};
pub const OUTPUT_MODULE: ShaderModule = ShaderModule {
    name: "output",
    parts: &[OUTPUT],
    int64: false,
};

pub const VISIBILITY_MODULE: ShaderModule = ShaderModule {
    name: "visibility",
    parts: &[VISIBILITY, SCREEN],
    int64: false,
};
pub const FILL_ANISOTROPIC_MODULE: ShaderModule = ShaderModule {
    name: "fill_anisotropic",
    parts: &[FILL_ANISOTROPIC, SCREEN],
    int64: false,
};
pub const DEPICTION_MODULE: ShaderModule = ShaderModule {
    name: "depiction",
    parts: &[DEPICTION, SCREEN],
    int64: false,
};
pub const DEPICTION_APPLY_MODULE: ShaderModule = ShaderModule {
    name: "depiction_apply",
    parts: &[DEPICTION_APPLY],
    int64: false,
};
pub const EDL_MODULE: ShaderModule = ShaderModule {
    name: "edl",
    parts: &[EDL],
    int64: false,
};

pub const BLEND_LAYERS_MODULE: ShaderModule = ShaderModule {
    name: "blend_layers",
    parts: &[BLEND_LAYERS],
    int64: false,
};
pub const SHADOW_TEXTURE_MODULE: ShaderModule = ShaderModule {
    name: "shadow_texture",
    parts: &[SHADOW_TEXTURE, POINT_PROJECTION],
    int64: false,
};

pub const SPLAT_MODULE: ShaderModule = ShaderModule {
    name: "splat",
    parts: &[SPLAT],
    int64: false,
};

/// Every module the GPU backend compiles (the naga validation test walks this list).
pub const BUCKET_SORT_MODULE: ShaderModule = ShaderModule {
    name: "bucket_sort",
    parts: &[BUCKET_SORT, POINT_PROJECTION],
    int64: false,
};

pub const SORTED_MODULE: ShaderModule = ShaderModule {
    name: "sorted splats",
    parts: &[SHADE, SORTED],
    int64: false,
};

pub const ALL: &[ShaderModule] = &[
    PROJECT64,
    PROJECT32,
    PROJECT_HW_MODULE,
    RESOLVE_MODULE,
    PEEL_REFERENCE_MODULE,
    FILL_BACKGROUND_MODULE,
    FILL_OCCLUDED_MODULE,
    FILL_PLANES_MODULE,
    ITERATE_MODULE,
    GATHER_MODULE,
    SHADE_MODULE,
    SMOOTH_MODULE,
    ANTIALIAS_MODULE,
    OUTPUT_MODULE,
    VISIBILITY_MODULE,
    FILL_ANISOTROPIC_MODULE,
    DEPICTION_MODULE,
    DEPICTION_APPLY_MODULE,
    EDL_MODULE,
    BLEND_LAYERS_MODULE,
    SHADOW_TEXTURE_MODULE,
    SPLAT_MODULE,
    BUCKET_SORT_MODULE,
    SORTED_MODULE,
];

#[cfg(test)]
mod tests {
    use super::*;

    /// Every WGSL module parses and validates with naga (no GPU needed): a broken shader fails
    /// plain `cargo test`.
    #[test]
    fn every_shader_validates_with_naga() {
        use naga::valid::{Capabilities, ValidationFlags, Validator};
        let mut failures = Vec::new();
        for m in ALL {
            let src = m.source();
            let module = match naga::front::wgsl::parse_str(&src) {
                Ok(m) => m,
                Err(e) => {
                    failures.push(format!("{}: {}", m.name, e.emit_to_string(&src)));
                    continue;
                }
            };
            let caps = if m.int64 {
                Capabilities::SHADER_INT64 | Capabilities::SHADER_INT64_ATOMIC_MIN_MAX
            } else {
                Capabilities::empty()
            };
            if let Err(e) = Validator::new(ValidationFlags::all(), caps).validate(&module) {
                failures.push(format!("{}: {}", m.name, e.emit_to_string(&src)));
            }
        }
        assert!(failures.is_empty(), "{}", failures.join("\n\n"));
    }

    #[test]
    fn the_64_bit_projection_needs_its_capability() {
        use naga::valid::{Capabilities, ValidationFlags, Validator};
        let src = PROJECT64.source();
        let module = naga::front::wgsl::parse_str(&src).unwrap();
        assert!(
            Validator::new(ValidationFlags::all(), Capabilities::empty())
                .validate(&module)
                .is_err()
        );
    }

    /// A struct's size in bytes as WGSL lays it out in `m`.
    fn wgsl_size(m: &ShaderModule, name: &str) -> usize {
        let module = naga::front::wgsl::parse_str(&m.source()).expect("parses");
        let ty = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("{}: no struct {name}", m.name));
        ty.1.inner.size(module.to_ctx()) as usize
    }

    /// Every uniform block has the size of the WGSL struct it fills: a field added on one
    /// side only fails here, not as garbage on a GPU.
    #[test]
    fn uniform_blocks_match_their_wgsl_structs() {
        use crate::passes as p;
        use std::mem::size_of;
        let blocks: &[(&ShaderModule, &str, usize)] = &[
            (&OUTPUT_MODULE, "View", size_of::<crate::ViewParams>()),
            (
                &FILL_BACKGROUND_MODULE,
                "Fill",
                size_of::<p::fill::gpu::FillBlock>(),
            ),
            (
                &ITERATE_MODULE,
                "Iterate",
                size_of::<crate::device::iterate::IterateBlock>(),
            ),
            (
                &PROJECT64,
                "Chunk",
                size_of::<p::project::gpu::ChunkBlock>(),
            ),
            (
                &PROJECT_HW_MODULE,
                "Chunk",
                size_of::<p::project::gpu::ChunkBlock>(),
            ),
            (
                &RESOLVE_MODULE,
                "Resolve",
                size_of::<p::project::gpu::ResolveBlock>(),
            ),
            (
                &GATHER_MODULE,
                "Gather",
                size_of::<p::shade::gpu::GatherBlock>(),
            ),
            (
                &SHADE_MODULE,
                "Shade",
                size_of::<p::shade::gpu::ShadeBlock>(),
            ),
            (
                &SMOOTH_MODULE,
                "Smooth",
                size_of::<p::smooth::gpu::SmoothBlock>(),
            ),
            (
                &ANTIALIAS_MODULE,
                "Antialias",
                size_of::<p::antialias::gpu::AntialiasBlock>(),
            ),
            (
                &VISIBILITY_MODULE,
                "Visibility",
                size_of::<p::visibility::gpu::VisibilityBlock>(),
            ),
            (
                &FILL_ANISOTROPIC_MODULE,
                "FillAnisotropic",
                size_of::<p::fill_anisotropic::gpu::FillAnisotropicBlock>(),
            ),
            (
                &DEPICTION_MODULE,
                "Depiction",
                size_of::<p::depiction::gpu::DepictionBlock>(),
            ),
            (&EDL_MODULE, "Edl", size_of::<p::edl::gpu::EdlBlock>()),
            (
                &BLEND_LAYERS_MODULE,
                "Blend",
                size_of::<p::blend_layers::gpu::BlendBlock>(),
            ),
            (
                &SHADOW_TEXTURE_MODULE,
                "Mark",
                size_of::<p::shadow_texture::gpu::MarkBlock>(),
            ),
            (
                &SPLAT_MODULE,
                "SplatBlock",
                size_of::<p::splat::gpu::SplatBlock>(),
            ),
            (
                &BUCKET_SORT_MODULE,
                "Sort",
                size_of::<p::bucket_sort::gpu::SortBlock>(),
            ),
            (
                &SORTED_MODULE,
                "SortedChunk",
                size_of::<p::splat::sorted_gpu::SortedChunk>(),
            ),
        ];
        let wrong: Vec<String> = blocks
            .iter()
            .filter_map(|&(m, name, rust)| {
                let wgsl = wgsl_size(m, name);
                (wgsl != rust).then(|| format!("{}: {name} is {wgsl} bytes, Rust {rust}", m.name))
            })
            .collect();
        assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    }

    /// A `const NAME: T = value;` of a module's WGSL, as a number.
    fn wgsl_const(m: &ShaderModule, name: &str) -> f64 {
        let src = m.source();
        let line = src
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("const {name}:")))
            .unwrap_or_else(|| panic!("{}: no const {name}", m.name));
        let v = line
            .split('=')
            .nth(1)
            .expect("a value")
            .trim()
            .trim_end_matches(';');
        let v = v.trim_end_matches('u');
        match v.strip_prefix("0x") {
            Some(h) => u64::from_str_radix(h, 16).expect("hex") as f64,
            None => v
                .parse()
                .unwrap_or_else(|_| panic!("{}: {name} = {v}", m.name)),
        }
    }

    /// Constants the WGSL repeats from Rust (WGSL cannot import them) hold the Rust values.
    #[test]
    fn wgsl_constants_mirror_the_rust_ones() {
        use crate::passes as p;
        let pairs: &[(&ShaderModule, &str, f64)] = &[
            (&OUTPUT_MODULE, "BACKGROUND", crate::BACKGROUND as f64),
            (&OUTPUT_MODULE, "HOLE", crate::HOLE as f64),
            (
                &EDL_MODULE,
                "BACKGROUND_RESPONSE",
                p::edl::cpu::BACKGROUND_RESPONSE as f64,
            ),
            (&EDL_MODULE, "SCALE", p::edl::cpu::SCALE as f64),
            (
                &FILL_ANISOTROPIC_MODULE,
                "EDGE_WEIGHT",
                p::fill_anisotropic::cpu::EDGE_WEIGHT as f64,
            ),
            (
                &FILL_ANISOTROPIC_MODULE,
                "CORNER_WEIGHT",
                p::fill_anisotropic::cpu::CORNER_WEIGHT as f64,
            ),
            (
                &SPLAT_MODULE,
                "MAX_FOOTPRINT",
                p::splat::MAX_FOOTPRINT as f64,
            ),
            (
                &PROJECT64,
                "WG",
                (p::project::gpu::POINTS_PER_GROUP / 8) as f64,
            ),
            (&BUCKET_SORT_MODULE, "MAX_K", p::bucket_sort::MAX_K as f64),
            (
                &FILL_PLANES_MODULE,
                "EDGE_COS2",
                p::project::cpu::EDGE_COS2 as f64,
            ),
            (
                &SORTED_MODULE,
                "MAX_FOOTPRINT",
                p::splat::MAX_FOOTPRINT as f64,
            ),
            (
                &SORTED_MODULE,
                "SORTED_MAX_ALPHA",
                p::splat::sorted::MAX_ALPHA as f64,
            ),
            (
                &SORTED_MODULE,
                "SORTED_ID_WEIGHT",
                p::splat::sorted::ID_WEIGHT as f64,
            ),
            (
                &SORTED_MODULE,
                "T_DRAW_SCALE",
                p::splat::transparent::DRAW_SCALE as f64,
            ),
            (
                &SORTED_MODULE,
                "T_MAX_GROUPS",
                stipple_core::grouping::TRANSPARENT_GROUPS as f64,
            ),
        ];
        for &(m, name, rust) in pairs {
            let w = wgsl_const(m, name);
            // f32 constants written with 8 significant digits.
            assert!(
                (w - rust).abs() <= 1e-7 * rust.abs().max(1.0),
                "{}: WGSL {name} = {w}, Rust {rust}",
                m.name
            );
        }
    }
}
