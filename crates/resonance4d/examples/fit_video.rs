//! Fitting a video from Rust: a jelly block drops onto a floor and wobbles; its video is
//! rendered from the true Young's modulus, and the fit recovers the modulus from the video
//! alone, starting three times too stiff:
//! `cargo run --release -p resonance4d --example fit_video`

use resonance4d::prelude::*;

/// Runs the example.
pub fn main() -> Result<(), Box<dyn std::error::Error>> {
    let text = include_str!("jelly_on_floor.toml");
    let mut config = SimConfig::parse(text, "jelly_on_floor.toml".as_ref())?;
    let truth = config.parts.clone();
    config.parts[0].youngs_modulus_pa *= 3.0; // where the fit starts
    let camera = Camera::look_at(
        64,
        48,
        40.0,
        [0.5, -0.3, 0.6],
        [0.5, 0.5, 0.35],
        [0.0, 0.0, 1.0],
    );
    let problem = ProblemBuilder::new(config)
        .camera(camera)
        .background([0.93, 0.92, 0.86])
        .rendered_from(&truth)?;

    let mut fit = FitConfig {
        // As written here: the automatic strategy would decide the stages and their budgets.
        strategy: Strategy::Fixed,
        iters: 20,
        free: Some(vec!["E".into()]),
        ..Default::default()
    };
    fit.init.enabled = false; // start from the config's E, not a Latin hypercube
    let outcome = run_fit(&problem, &fit, None, &mut NoHooks)?;
    let (e, e_true) = (
        outcome.parts[0].youngs_modulus_pa,
        truth[0].youngs_modulus_pa,
    );
    println!(
        "E: truth {e_true:.0} Pa, start {:.0} Pa, fit {e:.0} Pa",
        3.0 * e_true
    );
    assert!((e / e_true - 1.0).abs() < 0.05, "E off by more than 5%");
    Ok(())
}
