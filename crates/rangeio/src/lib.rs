//! Reading and writing range images: ABW Sun rasterfiles, sensor depth formats, PNG outputs.
