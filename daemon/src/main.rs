//! chaosd: the command line is [`daemon::cli`], shared with programs that extend chaosd.

fn main() -> std::process::ExitCode {
    daemon::cli::main()
}
