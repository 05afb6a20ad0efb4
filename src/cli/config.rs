use super::UsageError;

/// Arguments of `stereotag config`.
#[derive(Debug, clap::Args)]
pub struct Config {
    /// Print the defaults of this kind of settings: mapping, simulation, fuse or plan.
    #[arg(long = "default", value_name = "KIND")]
    kind: String,
}

impl Config {
    pub fn run(&self) -> anyhow::Result<()> {
        let text = match self.kind.as_str() {
            "mapping" => {
                serde_yaml_ng::to_string(&stereotag::sonar::map::MappingConfig::default())?
            }
            "simulation" => serde_yaml_ng::to_string(&stereotag::sim::SimConfig::default())?,
            "fuse" => serde_yaml_ng::to_string(&stereotag::fusion::FuseConfig::default())?,
            "plan" => serde_yaml_ng::to_string(&stereotag::plan::PlanConfig::default())?,
            other => {
                return Err(UsageError(format!(
                    "unknown settings kind `{other}`: expected mapping, simulation, fuse or plan"
                ))
                .into())
            }
        };
        print!("{text}");
        Ok(())
    }
}
