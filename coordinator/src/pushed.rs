//! Leaders' answers pushed at the cuts they reach (`P/leader/L/pushed/T`),
//! handed to the query waiting for that cut.
//!
//! A marginals query places a fresh cut; each leader, on reaching it, puts
//! its partial sums there unasked. The query takes them from here instead
//! of asking every leader in the same breath as the sensor: a leader is
//! then woken once per query (by the cut in its stream), not twice, which
//! on hosts shared by several processes is most of a query's wait. What
//! does not come in time is asked for as before ([`crate::driver::gather`]).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use tokio::sync::mpsc;

/// One pushed answer: the key it came on (naming the leader) and its bytes.
#[derive(Debug)]
pub(crate) struct Pushed {
    pub key: String,
    pub bytes: Vec<u8>,
}

/// The queries waiting for pushed answers, by the tag of their cut.
#[derive(Debug, Default)]
pub(crate) struct Pushes {
    waiting: Mutex<HashMap<u64, mpsc::UnboundedSender<Pushed>>>,
}

impl Pushes {
    /// A sample from `P/leader/*/pushed/*`: to the query waiting for its
    /// tag, if any (none: another coordinator's cut, or one given up on).
    pub fn take(&self, key: &str, bytes: Vec<u8>) {
        let Some(tag) = key.rsplit('/').next().and_then(|t| t.parse::<u64>().ok()) else {
            tracing::debug!(key, "a pushed answer on a key without a tag");
            return;
        };
        let waiting = self.waiting.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(tx) = waiting.get(&tag) {
            let _ = tx.send(Pushed {
                key: key.to_string(),
                bytes,
            });
        }
    }

    /// Starts waiting for the answers pushed at the cut tagged `tag`
    /// (before the cut is asked for: they may come before its placement
    /// does); the wait ends when the returned guard is dropped.
    pub(crate) fn wait_for(self: &Arc<Self>, tag: u64) -> Waiting {
        let (tx, rx) = mpsc::unbounded_channel();
        self.waiting
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(tag, tx);
        Waiting {
            pushes: self.clone(),
            tag,
            rx,
        }
    }
}

/// A query's wait for the answers pushed at its cut.
pub(crate) struct Waiting {
    pushes: Arc<Pushes>,
    tag: u64,
    pub rx: mpsc::UnboundedReceiver<Pushed>,
}

impl Drop for Waiting {
    fn drop(&mut self) {
        self.pushes
            .waiting
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .remove(&self.tag);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pushed_answer_reaches_the_query_waiting_for_its_tag_only_while_it_waits() {
        let pushes = Arc::new(Pushes::default());
        let mut seven = pushes.wait_for(7);
        pushes.take("p/leader/l0/pushed/7", vec![1]);
        pushes.take("p/leader/l1/pushed/8", vec![2]);
        pushes.take("p/leader/l1/pushed/x", vec![3]);
        let got = seven.rx.try_recv().unwrap();
        assert_eq!(
            (got.key.as_str(), got.bytes),
            ("p/leader/l0/pushed/7", vec![1])
        );
        assert!(seven.rx.try_recv().is_err(), "another tag's answer came");
        drop(seven);
        assert!(pushes.waiting.lock().unwrap().is_empty());
        pushes.take("p/leader/l0/pushed/7", vec![4]);
    }
}
