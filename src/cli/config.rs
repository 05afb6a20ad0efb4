use super::UsageError;
use stereotag::io::Settings;

/// Arguments of `stereotag config`.
#[derive(Debug, clap::Args)]
pub struct Config {
    /// Print the defaults of this kind of settings: mapping, simulation, fuse or plan.
    #[arg(long = "default", value_name = "KIND")]
    kind: String,
}

impl Config {
    pub fn run(&self) -> anyhow::Result<()> {
        let settings = Settings::from_name(&self.kind).ok_or_else(|| {
            UsageError(format!(
                "unknown settings kind `{}`: expected mapping, simulation, fuse or plan",
                self.kind
            ))
        })?;
        super::print_out(&settings.default_yaml())
    }
}
