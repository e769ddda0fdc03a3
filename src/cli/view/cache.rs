//! The scenes the viewer drew, the most recently used first, bounded in count and in bytes so
//! that exploring for hours does not grow memory: the least recently used scene goes first.
//! A handful of entries, so a list searched in order is all it needs.

use std::collections::VecDeque;
use std::sync::Arc;

use super::params::SceneKey;
use super::scene::Scene;

/// How many scenes the cache keeps at most.
pub const MAX_SCENES: usize = 24;

/// How many bytes of scenes (textures, volumes, downloads) the cache keeps at most; the newest
/// scene stays even when it alone is larger.
pub const MAX_BYTES: usize = 768 << 20;

/// The bounded cache of drawn scenes.
pub struct Cache {
    scenes: VecDeque<Arc<Scene>>,
    max_scenes: usize,
    max_bytes: usize,
    next_id: u64,
}

impl Cache {
    /// An empty cache keeping at most `max_scenes` scenes and `max_bytes` bytes.
    pub fn new(max_scenes: usize, max_bytes: usize) -> Self {
        Self {
            scenes: VecDeque::new(),
            max_scenes: max_scenes.max(1),
            max_bytes,
            next_id: 1,
        }
    }

    /// The scene drawn for `key`, marked as just used.
    pub fn find(&mut self, key: &SceneKey) -> Option<Arc<Scene>> {
        let at = self.scenes.iter().position(|s| &s.key == key)?;
        self.touch(at)
    }

    /// The scene with number `id`, marked as just used.
    pub fn get(&mut self, id: u64) -> Option<Arc<Scene>> {
        let at = self.scenes.iter().position(|s| s.id == id)?;
        self.touch(at)
    }

    /// Numbers `scene`, keeps it as the most recently used and drops the least recently used
    /// scenes beyond the bounds.
    pub fn insert(&mut self, mut scene: Scene) -> Arc<Scene> {
        scene.id = self.next_id;
        self.next_id += 1;
        let scene = Arc::new(scene);
        self.scenes.push_front(scene.clone());
        self.evict();
        scene
    }

    /// Drops the least recently used scenes while the bounds are exceeded (after a scene's
    /// downloads grew it, too).
    pub fn evict(&mut self) {
        while self.scenes.len() > 1
            && (self.scenes.len() > self.max_scenes || self.bytes() > self.max_bytes)
        {
            self.scenes.pop_back();
        }
    }

    /// How many scenes it holds.
    #[cfg(test)]
    pub fn scene_count(&self) -> usize {
        self.scenes.len()
    }

    /// The bytes its scenes hold.
    pub fn bytes(&self) -> usize {
        self.scenes.iter().map(|s| s.bytes()).sum()
    }

    /// Moves the scene at `at` to the front and returns it.
    fn touch(&mut self, at: usize) -> Option<Arc<Scene>> {
        let scene = self.scenes.remove(at)?;
        self.scenes.push_front(scene.clone());
        Some(scene)
    }
}

#[cfg(test)]
mod tests {
    use super::super::scene::{Content, Rendering};
    use super::*;
    use radiance_volume::{Aabb, GridDims, RadianceVolume};
    use volrender::DensityInterpolation;

    /// A scene of an `n`^3 volume for file `index`: `n^3 * 16` bytes of texture and as many of
    /// volume.
    fn scene(index: usize, n: usize) -> Scene {
        let volume = RadianceVolume::from_fn(GridDims::cube(n), Aabb::CUBE, 4, |_, _| {}).unwrap();
        let rendering = Rendering {
            density: DensityInterpolation::Physical,
            samples: 8,
            background: [0.0; 3],
        };
        Scene::new(
            SceneKey::File { index },
            format!("f{index}"),
            &volume,
            rendering,
            0.0,
            Content::Volume(volume.clone()),
        )
        .unwrap()
    }

    #[test]
    fn keeps_at_most_its_count_dropping_the_least_recently_used() {
        let mut cache = Cache::new(3, usize::MAX);
        for i in 0..3 {
            cache.insert(scene(i, 2));
        }
        // Using scene 0 makes scene 1 the least recently used.
        assert!(cache.find(&SceneKey::File { index: 0 }).is_some());
        cache.insert(scene(3, 2));
        assert_eq!(cache.scene_count(), 3);
        assert!(cache.find(&SceneKey::File { index: 1 }).is_none());
        assert!(cache.find(&SceneKey::File { index: 0 }).is_some());
        // Numbers are never reused: a dropped scene's number finds nothing.
        assert!(cache.get(2).is_none());
        assert_eq!(
            cache.get(4).map(|s| s.key.clone()),
            Some(SceneKey::File { index: 3 })
        );
    }

    #[test]
    fn keeps_at_most_its_bytes_but_always_the_newest() {
        // Each 4^3 scene holds 2 * 4^3 * 16 = 2048 bytes.
        let mut cache = Cache::new(100, 5000);
        for i in 0..5 {
            cache.insert(scene(i, 4));
            assert!(cache.bytes() <= 5000);
        }
        assert_eq!(cache.scene_count(), 2);
        let big = cache.insert(scene(9, 16));
        assert_eq!(cache.scene_count(), 1);
        assert!(big.bytes() > 5000 && cache.get(big.id).is_some());
    }
}
