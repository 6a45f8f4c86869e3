//! The command-line reference (docs/cli.md) is what the binaries print: regenerated here by
//! `scripts/cli-reference` from the built binaries and compared line for line.

#[test]
fn the_cli_reference_is_what_the_binaries_print() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let bin_dir = tests::bin("chaosctl");
    let o = std::process::Command::new("bash")
        .arg(root.join("scripts/cli-reference"))
        .env("CHAOSD_BIN", bin_dir.parent().unwrap())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let fresh = String::from_utf8(o.stdout).unwrap();
    let book = std::fs::read_to_string(root.join("docs/cli.md")).unwrap();
    if let Some((i, (a, b))) = fresh
        .lines()
        .zip(book.lines())
        .enumerate()
        .find(|(_, (a, b))| a != b)
    {
        panic!(
            "docs/cli.md line {} differs from the binaries' help (run `scripts/cli-reference > docs/cli.md`):\n  help: {a}\n  book: {b}",
            i + 1
        );
    }
    assert_eq!(
        fresh.lines().count(),
        book.lines().count(),
        "docs/cli.md is out of date: run `scripts/cli-reference > docs/cli.md`"
    );
    // Every chaosctl command is there, the live ones and the offline ones.
    for c in [
        "simulate",
        "record start",
        "export",
        "replay",
        "obstacle add",
        "watch",
    ] {
        assert!(book.contains(&format!("`chaosctl {c}`")), "{c}");
    }
}
