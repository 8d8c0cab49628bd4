//! The viewer's side panel (Tab shows and hides it): every option of `stipple render`, by
//! the flag's own name, with its help, read from the same `clap` definitions the command line
//! uses ([`crate::api::render_options`]), so names, ranges, defaults and error messages have
//! one source of truth. Apply parses the options exactly as the command line would
//! ([`crate::api::parse_render_args`]) and redraws with them; a bad value shows clap's own
//! message and changes nothing.
//!
//! Left out: what writes files (`-o`, `--depth-out`, …: the viewer's P and C keys do that),
//! and the camera flags (the mouse and keys move the camera).

/// Options the panel does not show.
const LEFT_OUT: &[&str] = &[
    "output",
    "depth-out",
    "camera-out",
    "normal-out",
    "save-normals",
    "layer-images",
    "stats",
    "eye",
    "target",
    "up",
    "fov",
    "ortho",
    "camera",
    "size",
    "help",
];

/// One option as the panel edits it.
#[derive(Clone, Debug)]
pub struct Opt {
    pub long: String,
    pub takes_value: bool,
    pub help: String,
    /// A value (empty: the default) or, for a switch, "on" / "".
    pub value: String,
}

/// What the panel's buttons asked for this frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Actions {
    /// Apply: redraw with the options.
    pub apply: bool,
    /// Screenshot (as P), at [`Panel::screenshot_size`].
    pub screenshot: bool,
    /// Save the camera (as C).
    pub save_camera: bool,
    /// Frame everything (as F).
    pub frame_all: bool,
}

pub struct Panel {
    pub visible: bool,
    /// The screenshot size field: `WxH`, or empty for the window's size.
    pub shot_size: String,
    pub options: Vec<Opt>,
    filter: String,
    /// The input (file, scene or tree) the options apply to.
    pub input: Option<String>,
    /// The last Apply's error (clap's message, or the reload's).
    pub error: Option<String>,
}

impl Panel {
    /// The panel for `render`'s options, holding the values of `given` (the command line's
    /// tokens after `view`).
    pub fn new(given: &[String], input: Option<String>) -> Panel {
        let mut options: Vec<Opt> = crate::api::render_options()
            .into_iter()
            .filter(|o| !LEFT_OUT.contains(&o.long.as_str()))
            .map(|o| Opt {
                long: o.long,
                takes_value: o.takes_value,
                help: o.help,
                value: String::new(),
            })
            .collect();
        let mut k = 0;
        while k < given.len() {
            let t = &given[k];
            k += 1;
            let Some(name) = t.strip_prefix("--") else {
                continue;
            };
            let (name, inline) = match name.split_once('=') {
                Some((n, v)) => (n, Some(v.to_string())),
                None => (name, None),
            };
            if let Some(o) = options.iter_mut().find(|o| o.long == name) {
                o.value = if o.takes_value {
                    match inline {
                        Some(v) => v,
                        None => {
                            k += 1;
                            given.get(k - 1).cloned().unwrap_or_default()
                        }
                    }
                } else {
                    "on".into()
                };
            }
        }
        Panel {
            visible: false,
            shot_size: String::new(),
            options,
            filter: String::new(),
            input,
            error: None,
        }
    }

    /// The options set, as command-line tokens (the input first).
    pub fn args(&self) -> Vec<String> {
        let mut v: Vec<String> = self.input.iter().cloned().collect();
        for o in &self.options {
            if o.takes_value {
                if !o.value.trim().is_empty() {
                    v.push(format!("--{}={}", o.long, o.value.trim()));
                }
            } else if o.value == "on" {
                v.push(format!("--{}", o.long));
            }
        }
        v
    }

    /// The screenshot size field parsed: None for the window's size.
    pub fn screenshot_size(&self) -> Result<Option<(u32, u32)>, String> {
        match self.shot_size.trim() {
            "" => Ok(None),
            s => crate::args::parse_size(s)
                .map(Some)
                .map_err(|e| format!("screenshot size: {e}")),
        }
    }

    /// Draws the panel; what its buttons asked for, and the panel's width in points.
    pub fn ui(&mut self, ui: &mut egui::Ui) -> (Actions, f32) {
        let mut act = Actions::default();
        let r = egui::Panel::left("stipple-options")
            .default_size(300.0)
            .show(ui, |ui| {
                ui.heading("stipple render options");
                ui.label(
                    "The flags of `stipple render`, by name (hover for help). Empty: the default.",
                );
                ui.horizontal(|ui| {
                    ui.label("filter");
                    ui.text_edit_singleline(&mut self.filter);
                });
                ui.horizontal(|ui| {
                    if ui.button("Apply").clicked() {
                        act.apply = true;
                    }
                    if ui.button("Defaults").clicked() {
                        for o in &mut self.options {
                            o.value.clear();
                        }
                    }
                });
                ui.horizontal(|ui| {
                    act.screenshot = ui
                        .button("Screenshot")
                        .on_hover_text(
                            "P: a PNG of the view (stipple-view-N.png, or -o PREFIX), at the \
                             size on the right (WxH; empty: the window's)",
                        )
                        .clicked();
                    ui.add(
                        egui::TextEdit::singleline(&mut self.shot_size)
                            .desired_width(70.0)
                            .hint_text("WxH"),
                    )
                    .on_hover_text("the screenshot's size (empty: the window's)");
                    act.save_camera = ui
                        .button("Save camera")
                        .on_hover_text("C: the camera as JSON for stipple render --camera")
                        .clicked();
                    act.frame_all = ui.button("Frame all").on_hover_text("F").clicked();
                });
                if let Some(e) = &self.error {
                    ui.colored_label(egui::Color32::from_rgb(230, 90, 80), e);
                }
                ui.separator();
                let filter = self.filter.to_lowercase();
                egui::ScrollArea::vertical().show(ui, |ui| {
                    for o in &mut self.options {
                        if !filter.is_empty()
                            && !o.long.contains(&filter)
                            && !o.help.to_lowercase().contains(&filter)
                        {
                            continue;
                        }
                        ui.horizontal(|ui| {
                            if o.takes_value {
                                ui.label(format!("--{}", o.long)).on_hover_text(&o.help);
                                ui.add(
                                    egui::TextEdit::singleline(&mut o.value).desired_width(110.0),
                                )
                                .on_hover_text(&o.help);
                            } else {
                                let mut on = o.value == "on";
                                ui.checkbox(&mut on, format!("--{}", o.long))
                                    .on_hover_text(&o.help);
                                o.value = if on { "on".into() } else { String::new() };
                            }
                        });
                    }
                });
            });
        (act, r.response.rect.width())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_panel_holds_the_given_options_and_gives_them_back() {
        let given: Vec<String> = [
            "--no-lighting",
            "--colour-by",
            "elevation",
            "--layers=2",
            "-o",
            "x.png",
            "--eye",
            "1,2,3",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        let p = Panel::new(&given, Some("tile.laz".into()));
        let v = |name: &str| {
            p.options
                .iter()
                .find(|o| o.long == name)
                .map(|o| o.value.clone())
        };
        assert_eq!(v("no-lighting").as_deref(), Some("on"));
        assert_eq!(v("colour-by").as_deref(), Some("elevation"));
        assert_eq!(v("layers").as_deref(), Some("2"));
        assert_eq!(v("eye"), None, "camera flags are the mouse's");
        assert_eq!(v("output"), None, "outputs are the keys'");
        let args = p.args();
        assert_eq!(args[0], "tile.laz");
        assert!(args.contains(&"--no-lighting".to_string()));
        assert!(args.contains(&"--colour-by=elevation".to_string()));
        // What Apply parses is the command line's own parse.
        assert!(crate::api::parse_render_args(&args).is_ok());
        // A value the command line refuses, the panel's Apply refuses with clap's message.
        let mut bad = p;
        bad.options
            .iter_mut()
            .find(|o| o.long == "layers")
            .unwrap()
            .value = "two".into();
        let e = crate::api::parse_render_args(bad.args())
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("--layers") && e.contains("two"), "{e}");
    }
}
