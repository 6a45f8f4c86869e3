//! `chaosd-plant-mujoco` and `chaosd-mujoco-judge` find the MuJoCo library where they were linked from: the build records
//! `MUJOCO_DYNAMIC_LINK_DIR` as the binary's run path, so no `LD_LIBRARY_PATH` is needed.

fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if std::env::var_os("CARGO_FEATURE_MUJOCO").is_none() {
        return;
    }
    if let Ok(dir) = std::env::var("MUJOCO_DYNAMIC_LINK_DIR") {
        for bin in ["chaosd-plant-mujoco", "chaosd-mujoco-judge"] {
            println!("cargo::rustc-link-arg-bin={bin}=-Wl,-rpath,{dir}");
        }
    }
}
