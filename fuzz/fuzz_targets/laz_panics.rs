//! Shared by the targets that decode LAZ: the LAZ decoder (the `laz` crate) panics on some
//! corrupt chunks, and stipple's readers catch those panics and return an error. libFuzzer's
//! panic hook would abort on them before the reader could catch them, so panics raised
//! inside the `laz` crate are let through to the reader; any other panic aborts as usual.

static HOOK: std::sync::Once = std::sync::Once::new();

/// Installs the hook (once per process).
pub fn let_laz_panics_through() {
    HOOK.call_once(|| {
        let abort = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !info.location().is_some_and(|l| l.file().contains("/laz-")) {
                abort(info);
            }
        }));
    });
}
