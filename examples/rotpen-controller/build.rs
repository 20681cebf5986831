fn main() -> Result<(), plantc_codegen::Error> {
    plantc_codegen::Builder::new()
        .model("../../models/rotary_pendulum.plant")
        .controller("feedback_linearization")
        .controller("pole_placement")
        .parameter_set("thesis")
        .compile()?;
    Ok(())
}
