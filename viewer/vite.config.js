// Builds the viewer into dist/ (or the --outDir that CMake passes: <build>/viewer). Relative asset paths so
// the files can be served from any folder; no CDN, nothing fetched at run time.
import { defineConfig } from 'vite';

export default defineConfig({
  base: './',
  build: { outDir: 'dist', assetsDir: 'assets', chunkSizeWarningLimit: 2000, sourcemap: false },
});
