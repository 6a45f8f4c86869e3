//! Building the MuJoCo model: the robot's file as MuJoCo compiles it, the set-up's obstacles
//! as geoms, and chaosd's joints found in it by name.
//!
//! A URDF names its meshes `package://NAME/…`, which only a ROS workspace resolves; MuJoCo
//! would strip the folders and look beside the file. So the text is rewritten before MuJoCo
//! reads it: each package becomes a folder (`[plant.mujoco] packages`, or the nearest folder
//! above the file with the package's name, as example-robot-data lays itself out), and a
//! `<mujoco><compiler strippath="false"/></mujoco>` element keeps the paths whole.

use anyhow::{anyhow, bail, Context, Result};
use mujoco_rs::mujoco_c::{
    mjModel, mj_forward, mj_id2name, mjs_delete, mjs_findElement, mjs_firstElement,
    mjs_nextElement, mjtObj,
};
use mujoco_rs::prelude::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Where a sphere slot not in use waits, and its radius (m): far below the base.
pub const PARKED: ([f64; 3], f64) = ([0.0, 0.0, -100.0], 0.01);

/// The name prefix of the obstacle geoms this plant adds to the world.
pub const OBSTACLE_PREFIX: &str = "chaosd_obstacle_";

/// A joint's `qpos` and `qvel` addresses.
pub type Address = (usize, usize);

/// What the model is read from.
#[derive(Clone, Copy)]
pub enum Source<'a> {
    /// A URDF or MJCF file.
    File(&'a Path),
    /// A URDF text (a built-in robot), without meshes.
    Urdf(&'a str),
}

/// The compiled model and where chaosd's joints are in it.
pub struct Built {
    pub model: Box<MjModel>,
    /// `qpos` and `qvel` addresses of chaosd's joints, in chaosd's order.
    pub arm: Vec<Address>,
    /// The model's other joints (a gripper's fingers), welded where they stand.
    pub welded: Vec<String>,
    /// Body pairs that touch in the start pose, excluded from contact.
    pub excluded: Vec<(String, String)>,
    /// Ids of the obstacle geoms, one per sphere slot ([`super::scene::MAX`]), the set-up's first.
    pub obstacles: Vec<usize>,
}

/// Compiles `source` with `spheres` (centre, radius; m) as fixed world geoms at physics step
/// `h` (s), finds `joints` (chaosd's joint names) in it, welds its other joints and excludes
/// the body pairs that touch with the arm at `q0`.
pub fn build(
    source: Source<'_>,
    packages: &BTreeMap<String, PathBuf>,
    (spheres, q0): (&[([f64; 3], f64)], &[f64]),
    joints: &[String],
    h: f64,
) -> Result<Built> {
    let mut spec = match source {
        Source::File(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read {}", path.display()))?;
            if is_urdf(&text) {
                let text = prepare_urdf(&text, path, packages)?;
                MjSpec::from_xml_string(&text)
            } else {
                MjSpec::from_xml(path)
            }
            .map_err(|e| anyhow!("MuJoCo cannot load {}: {e:?}", path.display()))?
        }
        Source::Urdf(text) => MjSpec::from_xml_string(&with_compiler(text)?)
            .map_err(|e| anyhow!("MuJoCo cannot load the robot's URDF: {e:?}"))?,
    };
    spec.option_mut().timestep = h;
    // Every sphere the daemon may ever have, made now (a compiled model cannot grow): the
    // set-up's, and the rest parked far below the base until a live edit places them. Each on
    // a mocap body of its own: a geom of the world body never touches the first link (MuJoCo
    // filters parent-child contacts), and a mocap body moves without a joint.
    for i in 0..super::scene::MAX {
        let (c, r) = spheres.get(i).copied().unwrap_or(PARKED);
        let body = spec
            .world_body_mut()
            .add_body()
            .with_name(&format!("{OBSTACLE_PREFIX}body_{i}"))
            .with_mocap(true)
            .with_pos(c);
        body.add_geom()
            .with_name(&format!("{OBSTACLE_PREFIX}{i}"))
            .with_type(MjtGeomBase::mjGEOM_SPHERE)
            .with_size([r, 0.0, 0.0]);
    }
    // First pass: which joints are not chaosd's, and which of the arm's bodies touch in the
    // start pose. Those joints are welded where they are (a gripper stays as it is) and those
    // pairs never collide: their contact would be the model's own overlap, not a motion's.
    let first = compile(&mut spec)?;
    let (_, extra) = joint_map(first.ffi(), joints)?;
    let overlap = overlapping_bodies(&first, joints, q0)?;
    drop_equalities_on(&mut spec, first.ffi(), &extra)?;
    for name in &extra {
        let c = std::ffi::CString::new(name.as_str())?;
        // SAFETY: a live spec; the joint was found by this name in its compiled model.
        unsafe {
            let el = mjs_findElement(spec.ffi_mut(), mjtObj::mjOBJ_JOINT, c.as_ptr());
            if el.is_null() || mjs_delete(spec.ffi_mut(), el) != 0 {
                bail!("cannot weld the model's joint {name:?}");
            }
        }
    }
    for (a, b) in &overlap {
        spec.add_exclude().with_bodyname1(a).with_bodyname2(b);
    }
    let model = Box::new(compile(&mut spec)?);
    let (arm, _) = joint_map(model.ffi(), joints)?;
    let obstacles = (0..super::scene::MAX)
        .map(|i| {
            model
                .name_to_id(MjtObjBase::mjOBJ_GEOM, &format!("{OBSTACLE_PREFIX}{i}"))
                .ok_or_else(|| anyhow!("obstacle geom {i} missing after compiling"))
        })
        .collect::<Result<_>>()?;
    Ok(Built {
        model,
        arm,
        welded: extra,
        excluded: overlap,
        obstacles,
    })
}

/// Deletes the joint equalities (a URDF's `<mimic>`) that tie any of the `welded` joints: a
/// welded joint has nothing left to follow.
fn drop_equalities_on(spec: &mut MjSpec, m: &mjModel, welded: &[String]) -> Result<()> {
    let n = m.neq as usize;
    // SAFETY: MuJoCo's per-equality arrays have neq entries.
    let (kind, a, b) = unsafe {
        (
            std::slice::from_raw_parts(m.eq_type, n),
            std::slice::from_raw_parts(m.eq_obj1id, n),
            std::slice::from_raw_parts(m.eq_obj2id, n),
        )
    };
    let joint = |id: i32| (id >= 0).then(|| name_of(m, mjtObj::mjOBJ_JOINT, id as usize));
    let ties = |k: usize| {
        kind[k] as u32 == 2 // mjEQ_JOINT
            && [a[k], b[k]]
                .into_iter()
                .filter_map(joint)
                .any(|j| welded.contains(&j))
    };
    // The compiled equalities are the spec's, in order: walk both together, deleting as we go.
    // SAFETY: a live spec; each element is read before it is deleted.
    unsafe {
        let s = spec.ffi_mut();
        let mut el = mjs_firstElement(s, mjtObj::mjOBJ_EQUALITY);
        for k in 0..n {
            if el.is_null() {
                bail!("the model's equality constraints do not match its compiled form");
            }
            let next = mjs_nextElement(s, el);
            if ties(k) && mjs_delete(s, el) != 0 {
                bail!("cannot drop the equality constraint on a welded joint");
            }
            el = next;
        }
    }
    Ok(())
}

fn compile(spec: &mut MjSpec) -> Result<MjModel> {
    spec.compile()
        .map_err(|e| anyhow!("MuJoCo cannot compile the model: {e:?}"))
}

/// The pairs of the arm's bodies (by name) whose geoms touch with chaosd's joints at `q0`.
fn overlapping_bodies(
    model: &MjModel,
    joints: &[String],
    q0: &[f64],
) -> Result<Vec<(String, String)>> {
    let (arm, _) = joint_map(model.ffi(), joints)?;
    let mut data = MjData::new(model);
    let m = model.ffi();
    // SAFETY: addresses from the model's joint table; a valid model and its data.
    unsafe {
        let d = data.ffi_mut();
        for (i, &(qa, _)) in arm.iter().enumerate() {
            *d.qpos.add(qa) = q0[i];
        }
        mj_forward(m, d);
    }
    let d = data.ffi();
    let mut pairs = Vec::new();
    for c in 0..d.ncon.max(0) as usize {
        // SAFETY: `contact` holds ncon entries after a forward pass; geom ids are below ngeom.
        let (b1, b2) = unsafe {
            let c = &*d.contact.add(c);
            (
                *m.geom_bodyid.add(c.geom[0] as usize) as usize,
                *m.geom_bodyid.add(c.geom[1] as usize) as usize,
            )
        };
        let pair = (
            name_of(m, mjtObj::mjOBJ_BODY, b1),
            name_of(m, mjtObj::mjOBJ_BODY, b2),
        );
        let obstacle = |n: &str| n.starts_with(OBSTACLE_PREFIX);
        if b1 == 0 || b2 == 0 || obstacle(&pair.0) || obstacle(&pair.1) {
            continue; // the fixed base or an obstacle: not the arm's own overlap
        }
        if !pairs.contains(&pair) {
            pairs.push(pair);
        }
    }
    Ok(pairs)
}

fn is_urdf(text: &str) -> bool {
    text.contains("<robot")
}

/// A name MuJoCo keeps for an object, or "" when it has none.
pub fn name_of(m: &mjModel, kind: mjtObj, id: usize) -> String {
    // SAFETY: `id` is below the object count for `kind` (callers loop over it); MuJoCo returns
    // null for an unnamed object and a NUL-terminated string it owns otherwise.
    let p = unsafe { mj_id2name(m, kind as i32, id as i32) };
    if p.is_null() {
        String::new()
    } else {
        // SAFETY: non-null, NUL-terminated, alive as long as the model.
        unsafe { std::ffi::CStr::from_ptr(p) }
            .to_string_lossy()
            .into_owned()
    }
}

/// chaosd's joints' (qpos, qvel) addresses by name, and the names of the model's other joints.
fn joint_map(m: &mjModel, joints: &[String]) -> Result<(Vec<Address>, Vec<String>)> {
    let n = m.njnt as usize;
    // SAFETY: MuJoCo's per-joint arrays have njnt entries.
    let (kind, qpos, dof) = unsafe {
        (
            std::slice::from_raw_parts(m.jnt_type, n),
            std::slice::from_raw_parts(m.jnt_qposadr, n),
            std::slice::from_raw_parts(m.jnt_dofadr, n),
        )
    };
    let names: Vec<String> = (0..n).map(|j| name_of(m, mjtObj::mjOBJ_JOINT, j)).collect();
    let one_dof = |j: usize| matches!(kind[j] as u32, 2 | 3); // slide, hinge
    let mut arm = Vec::with_capacity(joints.len());
    for want in joints {
        let Some(j) = names.iter().position(|x| x == want) else {
            bail!(
                "the MuJoCo model has no joint {want:?} (chaosd's arm has {}; the model's: {})",
                joints.join(", "),
                names.join(", ")
            );
        };
        if !one_dof(j) {
            bail!("the MuJoCo model's joint {want:?} is not a hinge or slide joint");
        }
        arm.push((qpos[j] as usize, dof[j] as usize));
    }
    if (0..n).any(|j| !one_dof(j)) {
        bail!("the MuJoCo model has a free or ball joint: chaosd drives fixed-base arms");
    }
    let extra = (0..n)
        .filter(|&j| !joints.contains(&names[j]))
        .map(|j| names[j].clone())
        .collect();
    Ok((arm, extra))
}

/// The URDF with its `package://` paths made into folders and MuJoCo's compiler element.
fn prepare_urdf(text: &str, path: &Path, packages: &BTreeMap<String, PathBuf>) -> Result<String> {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find("package://") {
        out.push_str(&rest[..at]);
        let after = &rest[at + "package://".len()..];
        let end = after.find('/').unwrap_or(after.len());
        let name = &after[..end];
        let dir = package_dir(name, path, packages)?;
        out.push_str(&dir.display().to_string());
        rest = &after[end..];
    }
    out.push_str(rest);
    with_compiler(&out)
}

/// Where `package://name/` points: the configured folder, or the nearest folder above the
/// file named `name`.
fn package_dir(name: &str, urdf: &Path, packages: &BTreeMap<String, PathBuf>) -> Result<PathBuf> {
    if let Some(p) = packages.get(name) {
        return Ok(p.clone());
    }
    let abs = urdf
        .canonicalize()
        .with_context(|| format!("cannot resolve {}", urdf.display()))?;
    abs.ancestors()
        .find(|a| a.file_name().is_some_and(|f| f == name))
        .map(Path::to_path_buf)
        .ok_or_else(|| {
            anyhow!(
                "{} names meshes in package {name:?}, and no folder above it has that name: \
                 say where it is in [plant.mujoco] packages = {{ {name:?} = \"/path/to/{name}\" }}",
                urdf.display()
            )
        })
}

/// Adds `<mujoco><compiler strippath="false"/></mujoco>` inside `<robot>` (unless the URDF has
/// its own `<mujoco>` element), so that mesh paths are used as written.
fn with_compiler(urdf: &str) -> Result<String> {
    if urdf.contains("<mujoco") {
        return Ok(urdf.to_string());
    }
    let at = urdf
        .find("<robot")
        .ok_or_else(|| anyhow!("not a URDF: no <robot> element"))?;
    let close = at
        + urdf[at..]
            .find('>')
            .ok_or_else(|| anyhow!("not a URDF: the <robot> tag does not close"))?
        + 1;
    Ok(format!(
        "{}<mujoco><compiler strippath=\"false\" discardvisual=\"true\"/></mujoco>{}",
        &urdf[..close],
        &urdf[close..]
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn package_paths_become_the_folder_named_like_the_package() {
        let dir = std::env::temp_dir().join(format!("chaosd-mj-{}", std::process::id()));
        let urdf_dir = dir.join("share/example-robot-data/robots/arm/urdf");
        std::fs::create_dir_all(&urdf_dir).unwrap();
        let file = urdf_dir.join("arm.urdf");
        std::fs::write(&file, "x").unwrap();
        let text = r#"<robot name="a"><link name="l"><collision><geometry><mesh filename="package://example-robot-data/robots/arm/meshes/l.stl"/></geometry></collision></link></robot>"#;
        let out = prepare_urdf(text, &file, &BTreeMap::new()).unwrap();
        let root = dir.join("share/example-robot-data").canonicalize().unwrap();
        assert!(
            out.contains(&format!("{}/robots/arm/meshes/l.stl", root.display())),
            "{out}"
        );
        assert!(out.contains("<robot name=\"a\"><mujoco><compiler strippath=\"false\""));
        let e = prepare_urdf(
            &text.replace("example-robot-data", "elsewhere"),
            &file,
            &BTreeMap::new(),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("packages = { \"elsewhere\""), "{e}");
        let mut given = BTreeMap::new();
        given.insert("elsewhere".to_string(), PathBuf::from("/opt/x"));
        let out = prepare_urdf(
            &text.replace("example-robot-data", "elsewhere"),
            &file,
            &given,
        )
        .unwrap();
        assert!(out.contains("/opt/x/robots/arm/meshes/l.stl"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
