//! What `stipple render` does between reading its input and writing its outputs, for
//! programs that embed the command line's behaviour (the Python package, `crates/stipple-py`):
//! options are parsed by the same `clap` definitions as the command line's flags, so names,
//! ranges, defaults and error messages are one source of truth for both.

use crate::cmd::render::RenderArgs;
use crate::Result;
use clap::{CommandFactory, FromArgMatches};
use stipple_core::Camera;
use stipple_render::{Frame, Pipeline, PreparedCloud, Renderer};
use stipple_scene::LoadedScene;

/// The input of `stipple render`, read (or generated) and with its camera.
pub struct Loaded {
    pub cloud: PreparedCloud,
    /// The input's name for messages.
    pub label: String,
    pub camera: Camera,
    /// The scene file's settings, when the input is one.
    pub scene: Option<LoadedScene>,
    /// The cloud is a cut of a `.stlod` tree or of a COPC file chosen for `camera`.
    pub tree: bool,
}

/// Reads the input the arguments name (a cloud file, a scene file, a tree's cut for the
/// camera, or a demo scene) and builds the camera from the camera arguments, as `stipple
/// render` does.
pub fn load(a: &RenderArgs) -> Result<Loaded> {
    let input = a.source.input.as_deref();
    // A tree, or a COPC file beyond the point budget: the cut the camera needs.
    let cut = match input {
        Some(p) if crate::lod::is_tree(p) => Some(crate::lod::load_cut(p, &a.camera, &a.lod)?),
        Some(p) if stipple_io::copc::is_copc(p) => crate::lod::load_copc_cut(p, &a.camera, &a.lod)?,
        _ => None,
    };
    if let Some((cloud, label, camera)) = cut {
        return Ok(Loaded {
            cloud,
            label,
            camera,
            scene: None,
            tree: true,
        });
    }
    if let Some(p) = input.filter(|p| stipple_scene::is_scene(p)) {
        let (cloud, s, camera) = crate::look::load_scene(p, &a.camera)?;
        return Ok(Loaded {
            cloud,
            label: s.label.clone(),
            camera,
            scene: Some(s),
            tree: false,
        });
    }
    let (cloud, label) = a.source.load()?;
    let camera = a.camera.build(&cloud.cloud)?;
    Ok(Loaded {
        cloud,
        label,
        camera,
        scene: None,
        tree: false,
    })
}

/// A finished frame and what was decided on the way.
pub struct Rendered {
    pub frame: Frame,
    /// The pipeline that drew it (after `--pipeline auto` chose).
    pub pipeline: Pipeline,
    /// The line describing the shadows made, if any.
    pub shadow_line: Option<String>,
    /// Milliseconds the frame itself took (after the preparation: normals, shadows).
    pub ms: f64,
}

/// What a frame shows besides the cloud: the camera, the scene file's settings (if the input
/// is one), whether the cloud is a tree's cut, and the input's name for messages.
pub struct View<'a> {
    pub camera: &'a Camera,
    pub scene: Option<&'a LoadedScene>,
    pub tree: bool,
    pub label: &'a str,
}

/// What a frame is drawn with once the cloud is prepared: the pipeline (after `--pipeline
/// auto` chose) and the line describing the shadows made, if any.
pub struct Prepared {
    pub pipeline: Pipeline,
    pub shadow_line: Option<String>,
}

/// Colours the cloud as asked, chooses the pipeline (estimating or re-orienting normals where
/// it needs them) and applies the look (a scene's lights, layers, opacity, shadows): what
/// every frame of `view` shares. `note` receives each line the user should read.
pub fn prepare(
    a: &RenderArgs,
    cloud: &mut PreparedCloud,
    view: &View<'_>,
    renderer: &mut Renderer,
    note: &mut dyn FnMut(&str),
) -> Result<Prepared> {
    prepare_progressively(a, cloud, view, renderer, note, None).map(|(p, _)| p)
}

/// [`prepare`] taking at most `first_samples` shadow samples per light now (None: all), and
/// what is left to refine (see [`crate::look::ShadowRefinement`]).
pub fn prepare_progressively(
    a: &RenderArgs,
    cloud: &mut PreparedCloud,
    view: &View<'_>,
    renderer: &mut Renderer,
    note: &mut dyn FnMut(&str),
    first_samples: Option<u32>,
) -> Result<(Prepared, Option<crate::look::ShadowRefinement>)> {
    let View {
        camera,
        scene,
        tree,
        label,
    } = *view;
    for line in a.colour.apply(cloud, label)? {
        note(&line);
    }
    let peeled = crate::look::layers(&a.look, scene) > 1;
    let see_through = !peeled && crate::look::see_through(&a.look, scene, cloud);
    let (mut pipe, notes) = a
        .pipeline
        .choose(cloud, camera, tree, peeled, see_through)?;
    for n in &notes {
        note(n);
    }
    let (shadow_line, refine) = crate::look::apply_progressively(
        cloud,
        &mut pipe,
        scene,
        &a.look,
        a.pipeline.background.is_some(),
        renderer,
        first_samples,
    )?;
    if let Some(sp) = pipe
        .splat
        .filter(|s| s.mode == stipple_render::SplatMode::Transparent)
    {
        // Computed once here (kept by the cloud for every frame): say what it made.
        let cov = cloud.coverage(sp.c, sp.coverage);
        let dup = 100.0 * cov.duplicates as f64 / cloud.cloud.len().max(1) as f64;
        note(&match cov.enlarged {
            None => format!(
                "transparent splats: {} groups, {} splats duplicated (+{dup:.0}%) so that each \
                 group covers the surface",
                cov.groups, cov.duplicates
            ),
            Some((most, mean)) => format!(
                "transparent splats: {} groups, splats enlarged {mean:.2}× on average (at \
                 most {most:.2}×) so that each group covers the surface, {} duplicated \
                 (+{dup:.1}%) where no neighbour of a group was",
                cov.groups, cov.duplicates
            ),
        });
    }
    if a.layer_images.is_some() {
        if pipe.layers == 1 {
            return Err(anyhow::anyhow!("--layer-images needs --layers N (N > 1)"));
        }
        pipe.keep_layers = true;
    }
    Ok((
        Prepared {
            pipeline: pipe,
            shadow_line,
        },
        refine,
    ))
}

/// Colours the cloud as asked, chooses the pipeline (estimating or re-orienting normals where
/// it needs them), applies the look (a scene's lights, layers, opacity, shadows) and renders
/// (see [`prepare`]). `note` receives each line the user should read, as it happens.
pub fn render_prepared(
    a: &RenderArgs,
    cloud: &mut PreparedCloud,
    view: &View<'_>,
    renderer: &mut Renderer,
    note: &mut dyn FnMut(&str),
) -> Result<Rendered> {
    let Prepared {
        pipeline: pipe,
        shadow_line,
    } = prepare(a, cloud, view, renderer, note)?;
    let t0 = std::time::Instant::now();
    let frame = renderer.render(cloud, view.camera, &pipe)?;
    Ok(Rendered {
        frame,
        pipeline: pipe,
        shadow_line,
        ms: t0.elapsed().as_secs_f64() * 1e3,
    })
}

/// One option of `stipple render`: its long name (`fill-iterations`) and whether it takes a
/// value (a switch such as `--edl` does not).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OptionInfo {
    pub long: String,
    pub takes_value: bool,
    pub help: String,
}

/// `stipple render`'s options, as its `--help` lists them.
pub fn render_options() -> Vec<OptionInfo> {
    let cmd = RenderCommand::command();
    cmd.get_arguments()
        .filter_map(|arg| {
            let long = arg.get_long()?.to_string();
            let takes_value = arg.get_action().takes_values();
            Some(OptionInfo {
                long,
                takes_value,
                help: arg.get_help().map(|h| h.to_string()).unwrap_or_default(),
            })
        })
        .collect()
}

/// Parses `stipple render`'s options (without the program or subcommand name: e.g.
/// `["--edl", "--fill-iterations", "2"]`) exactly as the command line does.
pub fn parse_render_args<I, S>(args: I) -> std::result::Result<RenderArgs, clap::Error>
where
    I: IntoIterator<Item = S>,
    S: Into<std::ffi::OsString> + Clone,
{
    let mut v: Vec<std::ffi::OsString> = vec!["render".into()];
    v.extend(args.into_iter().map(Into::into));
    let m = RenderCommand::command().try_get_matches_from(v)?;
    RenderCommand::from_arg_matches(&m).map(|c| c.args)
}

/// `stipple render` as a command of its own, for parsing and listing its options.
#[derive(clap::Parser)]
#[command(name = "render", color = clap::ColorChoice::Never)]
struct RenderCommand {
    #[command(flatten)]
    args: RenderArgs,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_parse_as_on_the_command_line() {
        let a = parse_render_args(["--layers", "3", "--stats"]).unwrap();
        assert_eq!(a.look.layers, Some(3));
        let e = parse_render_args(["--layers", "three"]).err().unwrap();
        assert!(e.to_string().contains("--layers"), "{e}");
        assert!(parse_render_args(["--no-such-flag"]).is_err());
    }

    #[test]
    fn options_are_listed_with_their_kind() {
        let o = render_options();
        let find = |n: &str| o.iter().find(|x| x.long == n).cloned();
        assert!(find("layers").unwrap().takes_value);
        assert!(!find("stats").unwrap().takes_value);
        assert!(find("no-such-flag").is_none());
    }
}
