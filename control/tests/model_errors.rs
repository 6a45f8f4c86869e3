//! Every bad description gets one clear error naming the element at fault, never a panic.

use control::model::{Chain, ModelError, MAX_URDF_BYTES};

/// A two-joint chain a — j1 — b — j2 — c, with `extra` spliced in before `</robot>`.
fn arm(extra: &str, j2_type: &str) -> String {
    format!(
        r#"<robot name="t">
  <link name="a"/>
  <link name="b"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <link name="c"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" velocity="1" effort="1"/></joint>
  <joint name="j2" type="{j2_type}"><parent link="b"/><child link="c"/><origin xyz="1 0 0"/>
    <limit lower="-1" upper="1" velocity="1" effort="1"/></joint>
  {extra}
</robot>"#
    )
}

fn err(text: &str) -> String {
    let e = Chain::from_urdf(text, None, None).unwrap_err();
    let s = e.to_string();
    assert!(!s.contains('\n') && s.len() < 400, "one short line: {s}");
    s
}

#[test]
fn a_good_arm_loads() {
    let c = Chain::from_urdf(&arm("", "revolute"), None, None).unwrap();
    assert_eq!((c.dof(), c.base.as_str(), c.tip.as_str()), (2, "a", "c"));
}

#[test]
fn not_xml_and_not_urdf() {
    assert!(err("this is not xml <").starts_with("not XML"));
    assert!(err("<sdf version='1.6'/>").contains("<sdf>"));
    assert_eq!(err("<robot name='x'/>"), ModelError::Empty.to_string());
}

#[test]
fn a_file_over_the_size_limit_is_refused_before_parsing() {
    let big = format!("<robot>{}</robot>", " ".repeat(MAX_URDF_BYTES));
    assert!(err(&big).contains("limit"));
}

#[test]
fn unknown_base_or_tip_names_the_link_and_lists_the_known_ones() {
    let t = arm("", "revolute");
    let e = Chain::from_urdf(&t, Some("nope"), None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("\"nope\"") && e.contains("base") && e.contains("\"a\""),
        "{e}"
    );
    let e = Chain::from_urdf(&t, None, Some("zz"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("\"zz\"") && e.contains("tip"), "{e}");
    let e = Chain::from_urdf(&t, Some("c"), Some("a"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("not on the path"), "{e}");
}

#[test]
fn a_joint_naming_a_missing_link() {
    let e = err(&arm(
        r#"<joint name="j3" type="fixed"><parent link="c"/><child link="ghost"/></joint>"#,
        "revolute",
    ));
    assert!(e.contains("\"j3\"") && e.contains("\"ghost\""), "{e}");
}

#[test]
fn two_parents_and_loops() {
    let e = err(&arm(
        r#"<joint name="j3" type="fixed"><parent link="a"/><child link="c"/></joint>"#,
        "revolute",
    ));
    assert!(
        e.contains("two parent joints") && e.contains("\"c\""),
        "{e}"
    );
    let looped = r#"<robot name="t"><link name="a"/><link name="b"/><link name="r"/>
        <joint name="x" type="fixed"><parent link="a"/><child link="b"/></joint>
        <joint name="y" type="fixed"><parent link="b"/><child link="a"/></joint></robot>"#;
    assert!(err(looped).contains("loop"), "{}", err(looped));
}

#[test]
fn several_leaves_ask_for_a_tip() {
    let e = err(&arm(
        r#"<link name="d"/><joint name="j3" type="fixed"><parent link="b"/><child link="d"/></joint>"#,
        "revolute",
    ));
    // Every leaf, the arm's end (most movable joints above it) first.
    assert!(
        e.contains("2 leaf links") && e.contains("\"c\" (2), \"d\" (1)"),
        "{e}"
    );
}

#[test]
fn a_misspelt_link_gets_the_nearest_names() {
    let text = arm(
        r#"<link name="gripper"/><joint name="j3" type="fixed"><parent link="c"/><child link="gripper"/></joint>"#,
        "revolute",
    );
    let e = Chain::from_urdf(&text, None, Some("Griper"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("did you mean \"gripper\"?"), "{e}");
    let far = Chain::from_urdf(&text, None, Some("tool_frame"))
        .unwrap_err()
        .to_string();
    assert!(!far.contains("did you mean"), "{far}");
}

#[test]
fn unsupported_and_unknown_joint_types_on_the_chain() {
    assert!(err(&arm("", "floating")).contains("\"j2\" on the chain is \"floating\""));
    assert!(err(&arm("", "planar")).contains("planar"));
    assert!(err(&arm("", "ball")).contains("\"ball\""));
}

#[test]
fn a_chain_longer_than_the_capacity_lists_its_joints() {
    let mut links = String::from(r#"<link name="l0"/>"#);
    let mut joints = String::new();
    for i in 1..=control::MAX_JOINTS + 1 {
        links.push_str(&format!(r#"<link name="l{i}"/>"#));
        joints.push_str(&format!(
            r#"<joint name="q{i}" type="continuous"><parent link="l{}"/><child link="l{i}"/></joint>"#,
            i - 1
        ));
    }
    let e = err(&format!("<robot name='long'>{links}{joints}</robot>"));
    assert!(
        e.contains(&format!("has {} movable joints", control::MAX_JOINTS + 1)),
        "{e}"
    );
    assert!(e.contains("\"q1\""), "{e}");
}

#[test]
fn non_finite_numbers_name_element_and_attribute() {
    let t = arm("", "revolute").replace(r#"<origin xyz="1 0 0"/>"#, r#"<origin xyz="1 nan 0"/>"#);
    let e = err(&t);
    assert!(
        e.contains("joint \"j2\" <origin>") && e.contains("xyz"),
        "{e}"
    );
    let t = arm("", "revolute").replace(r#"<mass value="1"/>"#, r#"<mass value="inf"/>"#);
    assert!(err(&t).contains("<mass>"));
    let t = arm("", "revolute").replace(r#"<origin xyz="1 0 0"/>"#, r#"<origin xyz="${l} 0 0"/>"#);
    assert!(err(&t).contains("${l}"));
}

#[test]
fn negative_mass_and_indefinite_inertia_name_the_link() {
    let t = arm("", "revolute").replacen(r#"<mass value="1"/>"#, r#"<mass value="-2"/>"#, 1);
    let e = err(&t);
    assert!(e.contains("\"b\"") && e.contains("-2"), "{e}");
    let t = arm("", "revolute").replacen(r#"ixx="1""#, r#"ixx="-1""#, 1);
    let e = err(&t);
    assert!(
        e.contains("\"b\"") && e.contains("negative principal moment"),
        "{e}"
    );
    // A thin rod (one zero moment) and a point mass are real descriptions' bodies: accepted.
    let rod = arm("", "revolute")
        .replacen(r#"ixx="1""#, r#"ixx="0""#, 1)
        .replacen(r#"iyy="1""#, r#"iyy="0.5""#, 1)
        .replacen(r#"izz="1""#, r#"izz="0.5""#, 1);
    assert!(Chain::from_urdf(&rod, None, None).is_ok());
}

#[test]
fn bad_limits_and_axes() {
    let t = arm("", "revolute").replacen(r#"lower="-1" upper="1""#, r#"lower="2" upper="1""#, 1);
    assert!(err(&t).contains("\"j1\": limit lower = 2 is above upper = 1"));
    let t = arm("", "revolute").replacen(r#"velocity="1""#, r#"velocity="-1""#, 1);
    assert!(err(&t).contains("velocity"));
    let t = arm("", "revolute").replace(r#"<axis xyz="0 0 1"/>"#, r#"<axis xyz="0 0 0"/>"#);
    assert!(err(&t).contains("zero axis"));
}

#[test]
fn mimic_on_the_chain_is_refused_but_off_the_chain_is_held() {
    let t = arm("", "revolute").replace(
        r#"<origin xyz="1 0 0"/>"#,
        r#"<origin xyz="1 0 0"/><mimic joint="j1"/>"#,
    );
    assert!(err(&t).contains("mimics"));
}

#[test]
fn problems_off_the_chain_do_not_stop_a_load() {
    // A broken number, a bad inertia and a planar joint, all on a branch the chain does not use.
    let branch = r#"<link name="x"><inertial><mass value="1"/><inertia ixx="-5" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
        <link name="y"/>
        <joint name="side" type="planar"><parent link="a"/><child link="x"/><origin xyz="${a} 0 0"/></joint>
        <joint name="side2" type="revolute"><parent link="x"/><child link="y"/></joint>
        <visual><geometry><mesh filename="package://nowhere/missing.dae"/></geometry></visual>"#;
    let c = Chain::from_urdf(&arm(branch, "revolute"), None, Some("c")).unwrap();
    assert_eq!(c.dof(), 2);
}

#[test]
fn unknown_builtin_lists_the_builtins() {
    let e = control::model::builtin("ur10").unwrap_err().to_string();
    assert!(e.contains("panda") && e.contains("planar3"), "{e}");
}
