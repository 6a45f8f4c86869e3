//! Reading a URDF into a plain tree of links and joints.
//!
//! Makers' descriptions carry much that a controller does not need: meshes behind `package://`
//! paths, materials, Gazebo plug-ins, transmissions, sometimes xacro that was never expanded.
//! Only `<link>`, `<inertial>` and `<joint>` are read here, and numbers are converted lazily: a
//! broken value is reported only if the chain actually uses that element, so a typo in the other
//! arm of a humanoid cannot stop loading this one. Undeclared namespace prefixes (`xacro:`
//! leftovers) are declared on the fly rather than refused.

use super::pose::Pose;
use super::ModelError;
use nalgebra::{Matrix3, Vector3};

/// Largest description accepted. Real arms' URDFs are 10-200 KB; a humanoid with inline meshes
/// stays under a few MB.
pub const MAX_URDF_BYTES: usize = 16 << 20;

/// A URDF as read: links and joints with their numbers still to be checked where they are used.
#[derive(Debug, Clone)]
pub struct Description {
    pub name: String,
    pub links: Vec<Link>,
    pub joints: Vec<Joint>,
}

#[derive(Debug, Clone)]
pub struct Link {
    pub name: String,
    /// `None` when the link has no `<inertial>` (URDF: a massless link).
    pub inertial: Option<Result<Inertial, ModelError>>,
}

/// A link's `<inertial>`: mass, the frame of its centre of mass, and the tensor in that frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inertial {
    pub mass: f64,
    pub origin: Pose,
    pub inertia: Matrix3<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointType {
    Revolute,
    Continuous,
    Prismatic,
    Fixed,
    Floating,
    Planar,
}

impl JointType {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "revolute" => Self::Revolute,
            "continuous" => Self::Continuous,
            "prismatic" => Self::Prismatic,
            "fixed" => Self::Fixed,
            "floating" => Self::Floating,
            "planar" => Self::Planar,
            _ => return None,
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Revolute => "revolute",
            Self::Continuous => "continuous",
            Self::Prismatic => "prismatic",
            Self::Fixed => "fixed",
            Self::Floating => "floating",
            Self::Planar => "planar",
        }
    }
}

/// A joint's `<limit>`. Missing attributes are unbounded (lower/upper ±∞, velocity/effort ∞).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    pub lower: f64,
    pub upper: f64,
    pub velocity: f64,
    pub effort: f64,
}

impl Limits {
    pub const NONE: Limits = Limits {
        lower: f64::NEG_INFINITY,
        upper: f64::INFINITY,
        velocity: f64::INFINITY,
        effort: f64::INFINITY,
    };
}

#[derive(Debug, Clone)]
pub struct Joint {
    pub name: String,
    pub kind: Result<JointType, ModelError>,
    pub parent: String,
    pub child: String,
    pub origin: Result<Pose, ModelError>,
    /// Unit axis (URDF default x).
    pub axis: Result<Vector3<f64>, ModelError>,
    pub limits: Result<Limits, ModelError>,
    /// The joint this one mimics, if any.
    pub mimic: Option<String>,
}

/// Parses URDF text. Only the tree's shape is checked here; see [`super::Chain`] for the rest.
pub fn parse(text: &str) -> Result<Description, ModelError> {
    if text.len() > MAX_URDF_BYTES {
        return Err(ModelError::TooLarge {
            bytes: text.len(),
            limit: MAX_URDF_BYTES,
        });
    }
    parse_declared(text)
}

/// Parses, declaring undeclared prefixes one at a time (bounded: a pathological file cannot loop).
fn parse_declared(text: &str) -> Result<Description, ModelError> {
    let mut src = std::borrow::Cow::Borrowed(text);
    for _ in 0..16 {
        match roxmltree::Document::parse(&src) {
            Ok(doc) => return read(&doc),
            Err(roxmltree::Error::UnknownNamespace(prefix, _)) => match declare(&src, &prefix) {
                Some(fixed) => src = std::borrow::Cow::Owned(fixed),
                None => break,
            },
            Err(e) => {
                return Err(ModelError::NotXml {
                    message: e.to_string(),
                })
            }
        }
    }
    Err(ModelError::NotXml {
        message: "too many undeclared namespace prefixes".into(),
    })
}

/// `text` with `xmlns:prefix` declared on its `<robot` start tag.
fn declare(text: &str, prefix: &str) -> Option<String> {
    let at = text.find("<robot")? + "<robot".len();
    let mut out = String::with_capacity(text.len() + 64);
    out.push_str(&text[..at]);
    out.push_str(&format!(
        " xmlns:{prefix}=\"urn:chaosd:undeclared:{prefix}\""
    ));
    out.push_str(&text[at..]);
    Some(out)
}

fn read(doc: &roxmltree::Document) -> Result<Description, ModelError> {
    let root = doc.root_element();
    if root.tag_name().name() != "robot" {
        return Err(ModelError::NotUrdf {
            found: root.tag_name().name().to_string(),
        });
    }
    let mut links = Vec::new();
    let mut joints = Vec::new();
    // Direct children only: a <joint> inside <transmission> is not a kinematic joint.
    for node in root.children().filter(|n| n.is_element()) {
        match node.tag_name().name() {
            "link" => links.push(read_link(node)?),
            "joint" => joints.push(read_joint(node)?),
            _ => {}
        }
    }
    Ok(Description {
        name: root.attribute("name").unwrap_or("").to_string(),
        links,
        joints,
    })
}

fn required<'a>(
    node: roxmltree::Node<'a, '_>,
    attr: &str,
    element: &str,
) -> Result<&'a str, ModelError> {
    node.attribute(attr).ok_or_else(|| ModelError::Missing {
        element: element.to_string(),
        attribute: attr.to_string(),
    })
}

fn child<'a, 'i>(node: roxmltree::Node<'a, 'i>, tag: &str) -> Option<roxmltree::Node<'a, 'i>> {
    node.children().find(|c| c.has_tag_name(tag))
}

fn read_link(node: roxmltree::Node) -> Result<Link, ModelError> {
    let name = required(node, "name", "<link>")?.to_string();
    let inertial = child(node, "inertial").map(|i| read_inertial(i, &format!("link {name:?}")));
    Ok(Link { name, inertial })
}

fn read_inertial(node: roxmltree::Node, owner: &str) -> Result<Inertial, ModelError> {
    let el = format!("{owner} <inertial>");
    let origin = read_origin(child(node, "origin"), &el)?;
    let mass_node = child(node, "mass").ok_or_else(|| ModelError::Missing {
        element: el.clone(),
        attribute: "<mass>".into(),
    })?;
    let mass = number(
        required(mass_node, "value", &format!("{el} <mass>"))?,
        &format!("{el} <mass>"),
        "value",
    )?;
    let inertia = match child(node, "inertia") {
        None => Matrix3::zeros(),
        Some(i) => {
            let e = format!("{el} <inertia>");
            let get = |a: &str| number(required(i, a, &e)?, &e, a);
            let (xx, xy, xz) = (get("ixx")?, get("ixy")?, get("ixz")?);
            let (yy, yz, zz) = (get("iyy")?, get("iyz")?, get("izz")?);
            Matrix3::new(xx, xy, xz, xy, yy, yz, xz, yz, zz)
        }
    };
    Ok(Inertial {
        mass,
        origin,
        inertia,
    })
}

fn read_joint(node: roxmltree::Node) -> Result<Joint, ModelError> {
    let name = required(node, "name", "<joint>")?.to_string();
    let el = format!("joint {name:?}");
    let kind_text = required(node, "type", &el)?;
    let kind = JointType::parse(kind_text).ok_or_else(|| ModelError::UnknownJointType {
        joint: name.clone(),
        kind: kind_text.to_string(),
    });
    let link_of = |tag: &str| -> Result<String, ModelError> {
        let n = child(node, tag).ok_or_else(|| ModelError::Missing {
            element: el.clone(),
            attribute: format!("<{tag}>"),
        })?;
        Ok(required(n, "link", &format!("{el} <{tag}>"))?.to_string())
    };
    let parent = link_of("parent")?;
    let child_link = link_of("child")?;
    let origin = read_origin(child(node, "origin"), &el);
    let axis = read_axis(child(node, "axis"), &el, &name);
    let limits = read_limits(child(node, "limit"), &el, &name);
    let mimic = child(node, "mimic").and_then(|m| m.attribute("joint").map(str::to_string));
    Ok(Joint {
        name,
        kind,
        parent,
        child: child_link,
        origin,
        axis,
        limits,
        mimic,
    })
}

fn read_origin(node: Option<roxmltree::Node>, owner: &str) -> Result<Pose, ModelError> {
    let Some(node) = node else {
        return Ok(Pose::IDENTITY);
    };
    let el = format!("{owner} <origin>");
    let xyz = triple(node.attribute("xyz"), &el, "xyz")?;
    let rpy = triple(node.attribute("rpy"), &el, "rpy")?;
    Ok(Pose::from_xyz_rpy(xyz, rpy))
}

fn read_axis(
    node: Option<roxmltree::Node>,
    owner: &str,
    joint: &str,
) -> Result<Vector3<f64>, ModelError> {
    let Some(node) = node else {
        return Ok(Vector3::x());
    };
    let a = triple(node.attribute("xyz"), &format!("{owner} <axis>"), "xyz")?;
    let norm = a.norm();
    if norm < 1e-12 {
        return Err(ModelError::ZeroAxis {
            joint: joint.to_string(),
        });
    }
    Ok(a / norm)
}

fn read_limits(
    node: Option<roxmltree::Node>,
    owner: &str,
    joint: &str,
) -> Result<Limits, ModelError> {
    let Some(node) = node else {
        return Ok(Limits::NONE);
    };
    let el = format!("{owner} <limit>");
    let get = |a: &str, default: f64| match node.attribute(a) {
        None => Ok(default),
        Some(v) => number(v, &el, a),
    };
    let l = Limits {
        lower: get("lower", f64::NEG_INFINITY)?,
        upper: get("upper", f64::INFINITY)?,
        velocity: get("velocity", f64::INFINITY)?,
        effort: get("effort", f64::INFINITY)?,
    };
    if l.lower > l.upper {
        return Err(ModelError::LimitOrder {
            joint: joint.to_string(),
            lower: l.lower,
            upper: l.upper,
        });
    }
    for (attribute, value) in [("velocity", l.velocity), ("effort", l.effort)] {
        if value < 0.0 {
            return Err(ModelError::NegativeLimit {
                joint: joint.to_string(),
                attribute,
                value,
            });
        }
    }
    Ok(l)
}

/// A finite number (URDF numbers are decimal text; `${pi/2}` from unexpanded xacro is not one).
fn number(text: &str, element: &str, attribute: &str) -> Result<f64, ModelError> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(ModelError::BadNumber {
            element: element.to_string(),
            attribute: attribute.to_string(),
            value: crate::basics::excerpt(text),
            expected: "a finite number",
        }),
    }
}

/// Three space-separated finite numbers; a missing attribute is zero (URDF's default).
fn triple(text: Option<&str>, element: &str, attribute: &str) -> Result<Vector3<f64>, ModelError> {
    let Some(text) = text else {
        return Ok(Vector3::zeros());
    };
    let bad = || ModelError::BadNumber {
        element: element.to_string(),
        attribute: attribute.to_string(),
        value: crate::basics::excerpt(text),
        expected: "three finite numbers",
    };
    let mut out = [0.0; 3];
    let mut parts = text.split_whitespace();
    for v in out.iter_mut() {
        *v = parts
            .next()
            .and_then(|p| p.parse::<f64>().ok())
            .filter(|x| x.is_finite())
            .ok_or_else(bad)?;
    }
    if parts.next().is_some() {
        return Err(bad());
    }
    Ok(Vector3::from(out))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn undeclared_xacro_prefixes_do_not_stop_a_load() {
        let text =
            r#"<robot name="r"><xacro:property name="a" value="1"/><link name="a"/></robot>"#;
        let d = parse(text).unwrap();
        assert_eq!(d.links.len(), 1);
    }

    #[test]
    fn numbers_are_checked_where_they_are_read() {
        let text = r#"<robot name="r"><link name="a"/><link name="b"/>
            <joint name="j" type="revolute"><parent link="a"/><child link="b"/>
            <origin xyz="0 0 ${l}"/></joint></robot>"#;
        let d = parse(text).unwrap();
        let e = d.joints[0].origin.clone().unwrap_err().to_string();
        assert!(
            e.contains("joint \"j\" <origin>") && e.contains("xyz"),
            "{e}"
        );
    }

    #[test]
    fn limits_out_of_order_are_refused() {
        let text = r#"<robot name="r"><link name="a"/><link name="b"/>
            <joint name="j" type="revolute"><parent link="a"/><child link="b"/>
            <limit lower="1" upper="-1" velocity="1" effort="1"/></joint></robot>"#;
        let d = parse(text).unwrap();
        assert!(matches!(
            d.joints[0].limits,
            Err(ModelError::LimitOrder { .. })
        ));
    }
}
