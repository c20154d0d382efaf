//! Progress of a long offline run (`mems-odometry offline`, `mems-sim`, `mems-plot`): an
//! indicatif bar on stderr, drawn only when stderr is a terminal (indicatif's terminal draw
//! target hides itself otherwise), so pipes, files, the journal and tests see nothing.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Redraws per second at most.
const HZ: u8 = 5;

/// A bar for `len` units (`None`: unknown, a counter), each named `unit`, titled `what`.
pub fn bar(len: Option<u64>, what: &str, unit: &str) -> ProgressBar {
    let bar = ProgressBar::with_draw_target(len, ProgressDrawTarget::stderr_with_hz(HZ));
    let template = match len {
        Some(_) => format!("{what} [{{bar:30}}] {{human_pos}}/{{human_len}} {unit} ({{eta}} left)"),
        None => format!("{what} {{spinner}} {{human_pos}} {unit} ({{per_sec}}, {{elapsed}})"),
    };
    let style = ProgressStyle::with_template(&template)
        .expect("a valid template")
        .progress_chars("=> ");
    bar.set_style(style);
    bar
}

#[cfg(test)]
mod tests {
    use std::io::IsTerminal as _;

    #[test]
    fn a_bar_is_drawn_only_on_a_terminal() {
        let off_terminal = !std::io::stderr().is_terminal();
        let bar = super::bar(Some(10), "test", "samples");
        bar.inc(3);
        assert_eq!(bar.is_hidden(), off_terminal);
        assert_eq!(bar.position(), 3);
        assert_eq!(
            super::bar(None, "test", "samples").is_hidden(),
            off_terminal
        );
    }
}
