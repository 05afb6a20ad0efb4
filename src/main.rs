//! The `stereotag` command line. Each subcommand lives in its own file under `cli/`.

mod cli;

fn main() {
    std::process::exit(cli::main());
}
