use super::UsageError;

/// Arguments of `stereotag config`.
#[derive(Debug, clap::Args)]
pub struct Config {
    /// Print the defaults of this kind of settings: mapping or simulation.
    #[arg(long = "default", value_name = "KIND")]
    kind: String,
}

impl Config {
    pub fn run(&self) -> anyhow::Result<()> {
        let text = match self.kind.as_str() {
            "mapping" => serde_yaml_ng::to_string(&stereotag::grid::MappingConfig::default())?,
            "simulation" => serde_yaml_ng::to_string(&stereotag::sim::SimConfig::default())?,
            other => {
                return Err(UsageError(format!(
                    "unknown settings kind `{other}`: expected mapping or simulation"
                ))
                .into())
            }
        };
        print!("{text}");
        Ok(())
    }
}
