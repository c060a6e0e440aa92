//! rmw_zenoh's names for a topic on Zenoh: the data key
//! `<domain>/<topic without its leading slash>/<DDS type name>/<type hash>`
//! (the DDS type name as `vision_msgs::msg::dds_::Detection2DArray_`, the
//! hash `RIHS01_<64 hex>` of REP 2011 on Jazzy and newer,
//! `TypeHashNotSupported` on Humble).

/// The DDS type name rmw_zenoh puts in keys for a ROS type name
/// (`pkg/msg/Type` → `pkg::msg::dds_::Type_`), or `None` when the name is
/// not of that shape.
pub fn dds_type_name(ros_type: &str) -> Option<String> {
    let mut parts = ros_type.split('/');
    let (Some(package), Some(kind), Some(name), None) =
        (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return None;
    };
    if [package, kind, name].iter().any(|p| p.is_empty()) {
        return None;
    }
    Some(format!("{package}::{kind}::dds_::{name}_"))
}

/// The topic's part of a key: the fully qualified topic without its
/// leading slash (and any trailing one).
pub fn topic_part(topic: &str) -> &str {
    topic.trim_start_matches('/').trim_end_matches('/')
}

/// The data key of a topic. `hash` is the type's `RIHS01_…` hash, or `*`
/// to match whatever a publisher writes there (Humble writes
/// `TypeHashNotSupported`).
pub fn data_key(domain: u32, topic: &str, dds_type: &str, hash: &str) -> String {
    format!("{domain}/{}/{dds_type}/{hash}", topic_part(topic))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_as_rmw_zenoh_writes_them() {
        let dds = dds_type_name("vision_msgs/msg/Detection2DArray").unwrap();
        assert_eq!(dds, "vision_msgs::msg::dds_::Detection2DArray_");
        assert_eq!(
            data_key(0, "/tracker/detections", &dds, "*"),
            "0/tracker/detections/vision_msgs::msg::dds_::Detection2DArray_/*"
        );
        assert_eq!(dds_type_name("vision_msgs/Detection2DArray"), None);
        assert_eq!(dds_type_name("a//b"), None);
    }
}
