//! One module per subcommand.

pub mod bench_solver;
pub mod mesh;
pub mod peer;
pub mod schema;
pub mod simulate;
