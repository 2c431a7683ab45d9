//! The iceoryx2 service type of every Sextant port: the POSIX shared-memory transport of
//! `iceoryx2::service::ipc::Service`, unchanged (same storage, connection, event and monitoring
//! mechanisms, so its services and nodes are the same files and segments), with one difference
//! in the process: the small reference-counted state iceoryx2 0.10 creates for every loaned
//! sample (`Publisher::loan_uninit` → `ChunkMutSharedState::new`) comes from a per-thread pool
//! of recycled blocks ([`PooledRc`]) instead of a fresh heap allocation (`Rc::new`) each time.
//! The fusion daemon publishes a solution per IMU sample; with this its loop allocates nothing
//! per sample once the pool holds the few blocks in flight.
//!
//! Single-threaded like iceoryx2's own `SingleThreaded` policy, which it replaces: the ports
//! and samples of this service are neither `Send` nor `Sync`, so a block is always taken and
//! returned on the thread that owns it.

use core::alloc::Layout;
use core::cell::{Cell, RefCell};
use core::fmt::Debug;
use core::marker::PhantomData;
use core::ops::Deref;
use core::ptr::NonNull;
use iceoryx2::service::internal::ServiceInternal;
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use iceoryx2_cal::arc_sync_policy::{ArcSyncPolicy, ArcSyncPolicyCreationError, LockGuard};
use iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator;
use iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator;
use iceoryx2_cal::{
    bag, dynamic_storage, event, hash, monitoring, reactor, resizable_shared_memory, serialize,
    shared_memory, static_storage, zero_copy_connection,
};

/// Inter-process zero-copy service over POSIX shared memory: `iceoryx2::service::ipc::Service`
/// with its per-sample state from [`PooledRc`].
#[derive(Debug, Clone)]
pub struct Service {}

impl iceoryx2::service::Service for Service {
    type StaticStorage = static_storage::recommended::Ipc;
    type ConfigSerializer = serialize::recommended::Recommended;
    type PersistentDynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::recommended::PersistentIpc<T>;
    type Bag = bag::recommended::Recommended;
    type DynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::recommended::Ipc<T>;
    type ServiceNameHasher = hash::recommended::Recommended;
    type SharedMemory = shared_memory::recommended::Ipc<PoolAllocator>;
    type ResizableSharedMemory = resizable_shared_memory::recommended::Ipc<PoolAllocator>;
    type Connection = zero_copy_connection::recommended::Ipc;
    type Event = event::recommended::Ipc;
    type Monitoring = monitoring::recommended::Ipc;
    type Reactor = reactor::recommended::Ipc;
    type ArcThreadSafetyPolicy<T: Send + Debug + Abandonable> = PooledRc<T>;
    type BlackboardMgmt<KeyType: Send + Sync + Debug + ZeroCopySend + 'static> =
        dynamic_storage::recommended::Ipc<KeyType>;
    type BlackboardPayload = shared_memory::recommended::Ipc<BumpAllocator>;
    type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
}

impl ServiceInternal<Service> for Service {}

/// A single-threaded reference-counted value (as `Rc<T>`) whose block, when the last
/// reference goes, returns to a per-thread free list of its layout and serves the next
/// [`PooledRc::new`] of that layout: after the first few samples no block is allocated.
pub struct PooledRc<T> {
    block: NonNull<Counted<T>>,
    /// Not `Send`/`Sync`: the count is a plain `Cell` and the pool is the thread's own.
    _single_thread: PhantomData<*const Counted<T>>,
}

/// A pooled block: the reference count and the value.
struct Counted<T> {
    count: Cell<usize>,
    value: T,
}

impl<T> PooledRc<T> {
    fn counted(&self) -> &Counted<T> {
        // SAFETY: the block holds an initialised `Counted<T>` for as long as a reference (this
        // one) is alive; only shared references are ever made to it.
        unsafe { self.block.as_ref() }
    }
}

impl<T: Send + Debug + Abandonable> ArcSyncPolicy<T> for PooledRc<T> {
    type LockGuard<'parent>
        = Guard<'parent, T>
    where
        Self: 'parent,
        T: 'parent;

    fn new(value: T) -> Result<Self, ArcSyncPolicyCreationError> {
        let layout = Layout::new::<Counted<T>>();
        let block = match take_block(layout) {
            Some(b) => b.cast::<Counted<T>>(),
            None => {
                // SAFETY: `Counted<T>` holds a `Cell<usize>`, so its size is not zero.
                let raw = unsafe { std::alloc::alloc(layout) };
                NonNull::new(raw.cast::<Counted<T>>())
                    .ok_or(ArcSyncPolicyCreationError::InsufficientResources)?
            }
        };
        // SAFETY: the block is unused memory of `Counted<T>`'s layout (fresh or returned to
        // the pool after its value was dropped).
        unsafe {
            block.write(Counted {
                count: Cell::new(1),
                value,
            })
        };
        Ok(Self {
            block,
            _single_thread: PhantomData,
        })
    }

    fn lock(&self) -> Self::LockGuard<'_> {
        Guard {
            value: &self.counted().value,
        }
    }
}

impl<T> Clone for PooledRc<T> {
    fn clone(&self) -> Self {
        let c = &self.counted().count;
        c.set(c.get() + 1);
        Self {
            block: self.block,
            _single_thread: PhantomData,
        }
    }
}

impl<T> Drop for PooledRc<T> {
    fn drop(&mut self) {
        let c = &self.counted().count;
        let n = c.get() - 1;
        c.set(n);
        if n == 0 {
            // SAFETY: the last reference: nothing reads the value after this, and the block is
            // handed on only once its value is dropped.
            unsafe {
                core::ptr::drop_in_place(self.block.as_ptr());
                give_block(self.block.cast(), Layout::new::<Counted<T>>());
            }
        }
    }
}

impl<T: Debug> Debug for PooledRc<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("PooledRc")
            .field("count", &self.counted().count.get())
            .field("value", &self.counted().value)
            .finish()
    }
}

impl<T: Abandonable> Abandonable for PooledRc<T> {
    /// As iceoryx2's `SingleThreaded` policy: the last reference abandons the value in place
    /// (its resources are not released; the block is not reused), any other one is dropped.
    unsafe fn abandon_in_place(this: NonNull<Self>) {
        // SAFETY: the caller passes a valid, constructed `PooledRc` it will not use again.
        let block = unsafe { this.as_ref() }.block;
        // SAFETY: the block holds an initialised `Counted<T>` while `this` refers to it.
        let count = unsafe { block.as_ref() }.count.get();
        if count == 1 {
            // SAFETY: the only reference, so nothing else reads the value; the pointer comes
            // from the block's own (allocation) pointer.
            unsafe {
                T::abandon_in_place(NonNull::new_unchecked(&raw mut (*block.as_ptr()).value))
            };
        } else {
            // SAFETY: `this` is valid and not used afterwards (the caller forgets it).
            unsafe { core::ptr::drop_in_place(this.as_ptr()) };
        }
    }
}

/// Access to the value of a [`PooledRc`].
pub struct Guard<'parent, T> {
    value: &'parent T,
}

impl<T> Deref for Guard<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        self.value
    }
}

impl<'parent, T: Send + Abandonable> LockGuard<'parent, T> for Guard<'parent, T> {}

/// Layouts a thread's pool keeps free lists for; blocks of any further layout are freed.
const POOL_LAYOUTS: usize = 16;

/// Free blocks kept per layout: more than the samples a port has in flight at once (the loans
/// the publisher allows); those beyond are freed.
const POOL_DEPTH: usize = 64;

/// The free blocks of one layout, as an intrusive list: a free block holds the address of the
/// next one in its first word (every block is at least a `Cell<usize>`), so the pool never
/// allocates for itself.
#[derive(Clone, Copy)]
struct FreeList {
    /// The layout of its blocks (None: this entry is not used yet).
    layout: Option<Layout>,
    head: Option<NonNull<u8>>,
    len: usize,
}

impl FreeList {
    /// The first free block, removed from the list.
    fn pop(&mut self) -> Option<NonNull<u8>> {
        let b = self.head?;
        // SAFETY: a free block's first word holds the next free block (or null).
        self.head = NonNull::new(unsafe { b.cast::<*mut u8>().read() });
        self.len -= 1;
        Some(b)
    }

    /// Put `b` at the head of the list.
    ///
    /// # Safety
    /// `b` is an unused block of the list's layout.
    unsafe fn push(&mut self, b: NonNull<u8>) {
        let next = self.head.map_or(core::ptr::null_mut(), NonNull::as_ptr);
        // SAFETY: the block is unused and at least a word in size and alignment.
        unsafe { b.cast::<*mut u8>().write(next) };
        self.head = Some(b);
        self.len += 1;
    }
}

/// A thread's free blocks, by layout.
struct Pool {
    lists: [FreeList; POOL_LAYOUTS],
}

impl Pool {
    /// The list of `layout`'s blocks (a new one if there is room).
    fn list(&mut self, layout: Layout) -> Option<&mut FreeList> {
        // The entries are taken in order and never given back, so the first unused one comes
        // after every used one.
        let list = self
            .lists
            .iter_mut()
            .find(|l| l.layout.is_none() || l.layout == Some(layout))?;
        list.layout = Some(layout);
        Some(list)
    }
}

impl Drop for Pool {
    fn drop(&mut self) {
        for list in &mut self.lists {
            while let (Some(layout), Some(b)) = (list.layout, list.pop()) {
                // SAFETY: allocated by `std::alloc::alloc` with this layout, and free.
                unsafe { std::alloc::dealloc(b.as_ptr(), layout) };
            }
        }
    }
}

thread_local! {
    static POOL: RefCell<Pool> = const {
        RefCell::new(Pool {
            lists: [FreeList {
                layout: None,
                head: None,
                len: 0,
            }; POOL_LAYOUTS],
        })
    };
}

/// A free block of `layout` from this thread's pool, if it has one.
fn take_block(layout: Layout) -> Option<NonNull<u8>> {
    POOL.try_with(|p| p.try_borrow_mut().ok()?.list(layout)?.pop())
        .ok()
        .flatten()
}

/// Return a block whose value is dropped to this thread's pool, or free it when the pool is
/// full or gone (a thread exiting).
///
/// # Safety
/// `b` was allocated with `layout` (by `std::alloc::alloc` or from this pool) and is unused.
unsafe fn give_block(b: NonNull<u8>, layout: Layout) {
    let kept = POOL
        .try_with(|p| {
            let Ok(mut p) = p.try_borrow_mut() else {
                return false;
            };
            match p.list(layout) {
                Some(list) if list.len < POOL_DEPTH => {
                    // SAFETY: per the function's contract.
                    unsafe { list.push(b) };
                    true
                }
                _ => false,
            }
        })
        .unwrap_or(false);
    if !kept {
        // SAFETY: per the function's contract.
        unsafe { std::alloc::dealloc(b.as_ptr(), layout) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::rc::Rc;

    /// A value that counts its drops.
    #[derive(Debug)]
    struct Tracked(Rc<Cell<u32>>, [u64; 3]);

    impl Drop for Tracked {
        fn drop(&mut self) {
            self.0.set(self.0.get() + 1);
        }
    }

    // `Tracked` holds an `Rc`, which is not `Send`; the policy's bound asks for `Send`
    // values, so the tests wrap the counter in a type that claims it (single thread only).
    #[derive(Debug)]
    struct SendTracked(Tracked);
    // SAFETY: used on the test's thread only.
    unsafe impl Send for SendTracked {}
    impl Abandonable for SendTracked {
        unsafe fn abandon_in_place(_this: NonNull<Self>) {}
    }

    #[test]
    fn the_value_drops_once_with_the_last_reference_and_its_block_is_reused() {
        let drops = Rc::new(Cell::new(0));
        let a = PooledRc::new(SendTracked(Tracked(drops.clone(), [1, 2, 3]))).unwrap();
        let first = a.block.cast::<u8>();
        let b = a.clone();
        assert_eq!(b.lock().0.1, [1, 2, 3]);
        drop(a);
        assert_eq!(drops.get(), 0, "a reference is left");
        assert_eq!(b.lock().0.1, [1, 2, 3]);
        drop(b);
        assert_eq!(drops.get(), 1, "dropped with the last reference");
        let c = PooledRc::new(SendTracked(Tracked(drops.clone(), [4, 5, 6]))).unwrap();
        assert_eq!(
            c.block.cast::<u8>(),
            first,
            "the freed block serves the next value"
        );
        assert_eq!(c.lock().0.1, [4, 5, 6]);
        drop(c);
        assert_eq!(drops.get(), 2);
    }

    #[test]
    fn many_values_in_flight_each_keep_their_own_block() {
        let drops = Rc::new(Cell::new(0));
        let all: Vec<_> = (0..POOL_DEPTH as u64 + 10)
            .map(|i| PooledRc::new(SendTracked(Tracked(drops.clone(), [i; 3]))).unwrap())
            .collect();
        for (i, v) in all.iter().enumerate() {
            assert_eq!(v.lock().0.1, [i as u64; 3]);
        }
        drop(all);
        assert_eq!(drops.get(), POOL_DEPTH as u32 + 10);
        // More than the pool keeps were freed; new values still come out right.
        let again: Vec<_> = (0..POOL_DEPTH as u64 + 10)
            .map(|i| PooledRc::new(SendTracked(Tracked(drops.clone(), [i + 100; 3]))).unwrap())
            .collect();
        for (i, v) in again.iter().enumerate() {
            assert_eq!(v.lock().0.1, [i as u64 + 100; 3]);
        }
    }
}
