//! chaosd with one more secondary task: everything `chaosd` does (`run`, `demo`,
//! `check-config`), and configs may say `secondary = "ready-posture"`.

fn main() -> std::process::ExitCode {
    if let Err(e) =
        control::secondary::custom::register(&[(custom_task::NAME, &custom_task::PANDA_READY)])
    {
        eprintln!("chaosd-posture: {e}");
        return std::process::ExitCode::from(2);
    }
    daemon::cli::main()
}
