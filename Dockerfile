# The auv-swarm image: one image for every service (router, world, channel, agents, recorder, collector, viewer).
# Where no image registry answers, build the base locally first:
#   BASE_IMAGE=$(docker/base-image.sh | tail -1) docker-compose build
# Dependencies install offline from docker/wheels/ when it holds wheels (base-image.sh fills it), else from the
# package index. Plug-in wheels in docker/plugins/ (planners, estimators: docs/containers.md) are installed beside the
# project's packages. The image keeps rerun's viewer binary (~280 MB): the compose `viewer` service serves the web
# viewer with it. Three stages keep the final image to the base, one dependency layer (rebuilt only when
# pyproject.toml or the wheels change) and one small layer of the project's own packages.
ARG BASE_IMAGE=python:3.11-slim

FROM ${BASE_IMAGE} AS deps
ENV PIP_DISABLE_PIP_VERSION_CHECK=1 PATH=/opt/venv/bin:$PATH
COPY docker/wheels/ /tmp/wheels/
COPY pyproject.toml /src/
RUN python3 -m venv /opt/venv \
 && if ls /tmp/wheels/*.whl >/dev/null 2>&1; then FROM_WHEELS="--no-index --find-links /tmp/wheels"; else FROM_WHEELS=""; fi \
 && DEPS=$(python3 -c 'import tomllib; print(" ".join(tomllib.load(open("/src/pyproject.toml", "rb"))["project"]["dependencies"]))') \
 && pip install --no-cache-dir $FROM_WHEELS $DEPS

FROM deps AS app
COPY . /src/
RUN if ls /tmp/wheels/*.whl >/dev/null 2>&1; then FROM_WHEELS="--no-index --find-links /tmp/wheels"; else FROM_WHEELS=""; fi \
 && pip install --no-cache-dir --no-deps --no-compile $FROM_WHEELS --target /opt/app /src \
 && if ls /src/docker/plugins/*.whl >/dev/null 2>&1; then \
      pip install --no-cache-dir --no-deps --no-compile --no-index --target /opt/app /src/docker/plugins/*.whl; fi

FROM ${BASE_IMAGE}
ENV PYTHONUNBUFFERED=1 PYTHONDONTWRITEBYTECODE=1 PATH=/opt/venv/bin:$PATH PYTHONPATH=/opt/app
COPY --from=deps /opt/venv /opt/venv
COPY --from=app /opt/app /opt/app
WORKDIR /runs
ENTRYPOINT ["python3", "-m", "auv_swarm"]
CMD ["--help"]
