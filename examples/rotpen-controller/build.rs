fn main() -> Result<(), plantc_codegen::Error> {
    plantc_codegen::Builder::new()
        .model("../../models/rotary_pendulum.plant")
        .controller("feedback_linearization")
        .controller("pole_placement")
        .controller("swing_up")
        .controller("sliding_mode")
        .parameter_set("thesis")
        .compile()?;
    Ok(())
}
