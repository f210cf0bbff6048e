"""Animal records."""

from fastapi import APIRouter, Query, Response

from app.deps import DbDep
from storage import animals
from storage.models import AnimalCreate, AnimalPublic, AnimalUpdate

router = APIRouter(prefix="/animals", tags=["animals"])


@router.post("", status_code=201, response_model=AnimalPublic)
def create_animal(data: AnimalCreate, db: DbDep):
    """Register an animal; the tag must be unique (409 otherwise)."""
    return animals.create_animal(db, data)


@router.get("", response_model=list[AnimalPublic])
def list_animals(db: DbDep, species: str | None = None, status: str | None = None,
                 tag: str | None = Query(None, description="substring of the tag"),
                 offset: int = Query(0, ge=0), limit: int = Query(100, ge=1, le=1000)):
    return animals.list_animals(db, species=species, status=status, tag=tag, offset=offset, limit=limit)


@router.get("/{animal_id}", response_model=AnimalPublic)
def get_animal(animal_id: int, db: DbDep):
    return animals.get_animal(db, animal_id)


@router.patch("/{animal_id}", response_model=AnimalPublic)
def update_animal(animal_id: int, data: AnimalUpdate, db: DbDep):
    """Change the fields sent; others keep their values."""
    return animals.update_animal(db, animal_id, data)


@router.delete("/{animal_id}", status_code=204)
def delete_animal(animal_id: int, db: DbDep) -> Response:
    """Delete an animal without sessions (409 if it has any: its measurements would be lost)."""
    animals.delete_animal(db, animal_id)
    return Response(status_code=204)
