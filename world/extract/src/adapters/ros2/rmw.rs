//! What rmw_zenoh expects of a publisher besides its payload:
//!
//! - an **attachment** on every sample: the keys and values
//!   `sequence_number` (i64), `source_timestamp` (i64, nanoseconds since
//!   the Unix epoch) and `source_gid` (16 bytes), one after another in
//!   Zenoh's own serialization (`zenoh-ext`: a string or a byte buffer
//!   is its length as a LEB128 varint then its bytes, an i64 its 8
//!   little-endian bytes). A subscriber refuses a sample without it.
//! - **liveliness tokens** that make the node and its publisher part of the
//!   ROS graph (`ros2 node list`, `ros2 topic list`):
//!   `@ros2_lv/<domain>/<zid>/<nid>/<eid>/NN/<enclave>/<namespace>/<node>`
//!   and, for the publisher, `…/MP/<enclave>/<namespace>/<node>/<topic>/<DDS
//!   type>/<type hash>/<QoS>`, every name with its slashes as `%`.

/// The attachment of one sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Attachment {
    pub sequence_number: i64,
    pub source_timestamp: i64,
    pub source_gid: [u8; 16],
}

fn varint(mut n: usize, out: &mut Vec<u8>) {
    loop {
        let byte = (n & 0x7f) as u8;
        n >>= 7;
        if n == 0 {
            out.push(byte);
            return;
        }
        out.push(byte | 0x80);
    }
}

fn bytes(b: &[u8], out: &mut Vec<u8>) {
    varint(b.len(), out);
    out.extend_from_slice(b);
}

impl Attachment {
    /// The attachment's bytes, as rmw_zenoh writes them.
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(64);
        bytes(b"sequence_number", &mut out);
        out.extend_from_slice(&self.sequence_number.to_le_bytes());
        bytes(b"source_timestamp", &mut out);
        out.extend_from_slice(&self.source_timestamp.to_le_bytes());
        bytes(b"source_gid", &mut out);
        bytes(&self.source_gid, &mut out);
        out
    }

    /// The sequence number of an attachment a ROS publisher sent, if it
    /// has one where rmw_zenoh puts it (for naming a bad message).
    pub fn sequence_of(attachment: &[u8]) -> Option<i64> {
        let key = b"sequence_number";
        let rest = attachment.strip_prefix(&[key.len() as u8][..])?;
        let rest = rest.strip_prefix(&key[..])?;
        let number: [u8; 8] = rest.get(..8)?.try_into().ok()?;
        Some(i64::from_le_bytes(number))
    }
}

/// A name in a liveliness token: its slashes as `%` (an empty name as `%`
/// too, since a key has no empty chunk).
pub fn mangle(name: &str) -> String {
    if name.is_empty() {
        return "%".to_string();
    }
    name.replace('/', "%")
}

/// Who publishes: the node and the entity ids of it and its publisher.
#[derive(Debug, Clone, PartialEq)]
pub struct Graph {
    pub domain: u32,
    /// The Zenoh session's id, as Zenoh prints it.
    pub zid: String,
    pub namespace: String,
    pub node: String,
}

/// rmw_zenoh's default QoS (reliable, volatile, keep last 10, no
/// deadline, lifespan or lease) written as its token writes a QoS equal
/// to the default: every field left empty.
pub const DEFAULT_QOS: &str = "::,:,:,:,,";

impl Graph {
    fn prefix(&self, entity: u32, kind: &str) -> String {
        format!(
            "@ros2_lv/{}/{}/0/{entity}/{kind}/%/{}/{}",
            self.domain,
            self.zid,
            mangle(&self.namespace),
            mangle(&self.node)
        )
    }

    /// The node's token.
    pub fn node_token(&self) -> String {
        self.prefix(0, "NN")
    }

    /// The token of the node's publisher `entity` on `topic`.
    pub fn publisher_token(&self, entity: u32, topic: &str, dds_type: &str, hash: &str) -> String {
        format!(
            "{}/{}/{dds_type}/{hash}/{DEFAULT_QOS}",
            self.prefix(entity, "MP"),
            mangle(topic)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_attachment_in_zenoh_serialization() {
        let a = Attachment {
            sequence_number: 3,
            source_timestamp: -1,
            source_gid: [7; 16],
        };
        let b = a.encode();
        assert_eq!(b[0], 15);
        assert_eq!(&b[1..16], b"sequence_number");
        assert_eq!(&b[16..24], &3i64.to_le_bytes());
        assert_eq!(Attachment::sequence_of(&b), Some(3));
        assert_eq!(b.len(), 16 + 8 + 17 + 8 + 11 + 17);
        assert_eq!(Attachment::sequence_of(&b[..20]), None);
    }

    #[test]
    fn tokens_as_rmw_zenoh_writes_them() {
        let g = Graph {
            domain: 0,
            zid: "ab12".into(),
            namespace: "/".into(),
            node: "idmesh".into(),
        };
        assert_eq!(g.node_token(), "@ros2_lv/0/ab12/0/0/NN/%/%/idmesh");
        assert_eq!(
            g.publisher_token(1, "/idmesh/markers", "visualization_msgs::msg::dds_::MarkerArray_", "RIHS01_x"),
            "@ros2_lv/0/ab12/0/1/MP/%/%/idmesh/%idmesh%markers/visualization_msgs::msg::dds_::MarkerArray_/RIHS01_x/::,:,:,:,,"
        );
    }
}
