//! Frame statistics: per step of the frame, its time and effect, keyed by [`PassId`].

/// A step of the frame as the statistics name it (see [`crate::schedule`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum PassId {
    Project,
    Splat,
    FillBackground,
    FillOccluded,
    Visibility,
    Shade,
    Smooth,
    Antialias,
    FillAnisotropic,
    Depiction,
    Edl,
    DepthCue,
    BlendBegin,
    BlendLayers,
    PeelReference,
    Compose,
    Output,
    ShadowTexture,
    BucketSort,
}

impl PassId {
    /// The name printed in statistics and benchmarks (snake_case, as the pass's folder).
    pub fn name(self) -> &'static str {
        match self {
            PassId::Project => "project",
            PassId::Splat => "splat",
            PassId::FillBackground => "fill_background",
            PassId::FillOccluded => "fill_occluded",
            PassId::Visibility => "visibility",
            PassId::Shade => "shade",
            PassId::Smooth => "smooth",
            PassId::Antialias => "antialias",
            PassId::FillAnisotropic => "fill_anisotropic",
            PassId::Depiction => "depiction",
            PassId::Edl => "edl",
            PassId::DepthCue => "depth_cue",
            PassId::BlendBegin => "blend_begin",
            PassId::BlendLayers => "blend_layers",
            PassId::PeelReference => "peel_reference",
            PassId::Compose => "compose",
            PassId::Output => "output",
            PassId::ShadowTexture => "shadow_texture",
            PassId::BucketSort => "bucket_sort",
        }
    }
}

impl std::fmt::Display for PassId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Time and effect of one pass in one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct PassStat {
    pub pass: PassId,
    pub ms: f64,
    pub iterations: u32,
    /// Pixels changed (fill passes) or points projected (project).
    pub count: u64,
}

impl PassStat {
    pub fn name(&self) -> &'static str {
        self.pass.name()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pass_names_are_distinct() {
        let all = [
            PassId::Project,
            PassId::Splat,
            PassId::FillBackground,
            PassId::FillOccluded,
            PassId::Visibility,
            PassId::Shade,
            PassId::Smooth,
            PassId::Antialias,
            PassId::FillAnisotropic,
            PassId::Depiction,
            PassId::Edl,
            PassId::DepthCue,
            PassId::BlendBegin,
            PassId::BlendLayers,
            PassId::PeelReference,
            PassId::Compose,
            PassId::Output,
            PassId::ShadowTexture,
            PassId::BucketSort,
        ];
        let mut n: Vec<&str> = all.iter().map(|p| p.name()).collect();
        n.sort();
        n.dedup();
        assert_eq!(n.len(), all.len());
    }
}
