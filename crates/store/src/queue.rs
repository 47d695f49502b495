//! Group commit of accepted records.
//!
//! Every ingest is one transaction with its own commit; with `synchronous = FULL` (SQLite) or
//! `synchronous_commit = on` (PostgreSQL) each commit waits for the disk. Under load, concurrent
//! requests on SQLite also queue for its single write lock, sleeping in the busy handler. The
//! [`IngestQueue`] has one writer task: it takes the records waiting when it is free (up to
//! `max_batch`) and writes them with [`Store::ingest_batch`] — one transaction, one commit,
//! each record in its own savepoint — then answers each request. A request is still answered
//! only after the commit that holds its record: acknowledgement-after-commit is unchanged, only
//! the number of commits per record falls. With one request at a time a batch is one record
//! and nothing waits.

use std::sync::Arc;

use tokio::sync::{mpsc, oneshot};

use super::{Ingest, Store, StoreError, StoreResult};

type Job = (Ingest, oneshot::Sender<StoreResult<usize>>);

/// The queue in front of [`Store::ingest`]. Cheap to clone; the writer task ends when the last
/// clone is dropped (after the records already queued are written).
#[derive(Clone)]
pub struct IngestQueue {
    store: Arc<dyn Store>,
    tx: Option<mpsc::Sender<Job>>,
}

impl IngestQueue {
    /// Start the writer task on the current tokio runtime. Outside a runtime (or with
    /// `max_batch <= 1`) every ingest is written directly, one transaction each.
    pub fn start(store: Arc<dyn Store>, max_batch: usize) -> IngestQueue {
        let handle = tokio::runtime::Handle::try_current().ok();
        let tx = match handle {
            Some(h) if max_batch > 1 => {
                let (tx, rx) = mpsc::channel::<Job>(4 * max_batch);
                h.spawn(writer(store.clone(), rx, max_batch));
                Some(tx)
            }
            _ => None,
        };
        IngestQueue { store, tx }
    }

    /// Write one accepted record; returns when it is committed (or failed), with how many
    /// webhook deliveries it queued.
    pub async fn ingest(&self, ing: Ingest) -> StoreResult<usize> {
        let Some(tx) = &self.tx else {
            return self.store.ingest(&ing).await;
        };
        let (done, wait) = oneshot::channel();
        if let Err(mpsc::error::SendError((ing, _))) = tx.send((ing, done)).await {
            // The writer is gone (shutting down): write directly.
            return self.store.ingest(&ing).await;
        }
        wait.await.unwrap_or_else(|_| {
            Err(StoreError::Shared(Arc::new(StoreError::Db(
                sqlx::Error::WorkerCrashed,
            ))))
        })
    }
}

async fn writer(store: Arc<dyn Store>, mut rx: mpsc::Receiver<Job>, max_batch: usize) {
    let mut jobs: Vec<Job> = Vec::with_capacity(max_batch);
    while rx.recv_many(&mut jobs, max_batch).await > 0 {
        let (ings, waiters): (Vec<Ingest>, Vec<_>) = jobs.drain(..).unzip();
        let results = store.ingest_batch(&ings).await;
        for (w, r) in waiters.into_iter().zip(results) {
            // A requester that went away (client disconnected) no longer listens; its record
            // is stored all the same, as it would be without the queue.
            let _ = w.send(r);
        }
    }
}
